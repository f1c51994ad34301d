//! Choosing a device of an ESI file the way a master identifies one, and resolving its modules:
//! the `FILE.xml#SEL` syntax every command shares.
//!
//! ```text
//! SEL    := DEVICE ('+' MODULE)*
//! DEVICE := TYPE                 type name, any case            EJ7211-0011
//!         | TYPE '/' REV         type name and revision         EJ7211-0011/0x001B000B
//!         | CODE ['/' REV]       product code [and revision]    0x1C2B2852/#x001B000B, 472590418
//!         | '@' N                position, 1-based, as `esi list` numbers them
//! MODULE := IDENT | NAME | ''    ModuleIdent number, module Type text, or the slot's default
//! ```
//! Numbers are `0x…` / `#x…` hex or decimal. A number is a product code; if no device has that
//! product code, a device whose `Type` text is that number. A `/` followed by something other
//! than a number is part of the type name. A type name matches the `Type` text
//! case-insensitively; when none does, a device `Name` (the old `--device NAME` form).
//!
//! * A selector several devices match (revisions of one product, or -0010 / -0011 variants that
//!   share a product code) picks the highest revision and says so in a note
//!   ([`Resolved::notes`]); one that matches nothing lists what the file has.
//! * Without a selector a file with one device is that device; a file with several is an error
//!   listing them with the syntax to pick one.
//! * The modules name the module of each slot instance in order ([`Device::resolve`]); slots
//!   not named get their default module.
//! * [`split_spec`] splits `FILE.xml#SEL` at the first `#` after `.xml` (any case), else at the
//!   first `#`; a caller that finds a file with the whole name should use it as is.

use super::{Device, EsiFile, ModuleChoice, ModuleError};
use std::fmt;
use std::str::FromStr;

/// Which device of a file (see the module docs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeviceSelector {
    /// `@N`: the N-th device (1-based).
    Position(usize),
    /// A product code, and a revision if given.
    Product {
        /// `Type ProductCode`.
        code: u32,
        /// `Type RevisionNo`.
        revision: Option<u32>,
    },
    /// A type name, and a revision if given.
    Type {
        /// `Type` text (matched case-insensitively).
        name: String,
        /// `Type RevisionNo`.
        revision: Option<u32>,
    },
}

/// A parsed `SEL`: the device and the modules per slot.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Selector {
    /// The device.
    pub device: DeviceSelector,
    /// The module of each slot instance, in order (may be fewer than the slots).
    pub modules: Vec<ModuleChoice>,
    /// The device part as written (a number is also tried as a type name).
    text: String,
}

impl fmt::Display for DeviceSelector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let rev = |r: &Option<u32>| r.map(|r| format!("/0x{r:08X}")).unwrap_or_default();
        match self {
            DeviceSelector::Position(n) => write!(f, "@{n}"),
            DeviceSelector::Product { code, revision } => {
                write!(f, "0x{code:08X}{}", rev(revision))
            }
            DeviceSelector::Type { name, revision } => write!(f, "{name}{}", rev(revision)),
        }
    }
}

impl Selector {
    /// A selector built in code (e.g. from the identity a master read): the device and the
    /// modules of its slots in order.
    pub fn new(device: DeviceSelector, modules: Vec<ModuleChoice>) -> Selector {
        Selector {
            text: device.to_string(),
            device,
            modules,
        }
    }
}

impl fmt::Display for Selector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.text)?;
        for m in &self.modules {
            match m {
                ModuleChoice::Default => write!(f, "+")?,
                other => write!(f, "+{other}")?,
            }
        }
        Ok(())
    }
}

/// Why no device could be chosen.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SelectError {
    /// The selector text is not valid.
    #[error("device selector {text:?}: {why}")]
    Syntax {
        /// The selector.
        text: String,
        /// What is wrong.
        why: String,
    },
    /// The file has no device.
    #[error("{file}: the file describes no device")]
    NoDevices {
        /// File name.
        file: String,
    },
    /// No selector and several devices.
    #[error(
        "{file}: the file describes {count} devices; pick one with {file}#SEL, SEL a type name \
         (TYPE or TYPE/REVISION), a product code (CODE or CODE/REVISION) or a position @N: {list}"
    )]
    Several {
        /// File name.
        file: String,
        /// Devices in the file.
        count: usize,
        /// The devices (`@1 0x00010402 (TYPE) revision 0x…`, bounded).
        list: String,
    },
    /// Nothing matches.
    #[error("{file}: no such device: {wanted}; the file has: {list}")]
    NoMatch {
        /// File name.
        file: String,
        /// What was asked for (`no device with product code 0x00010403`).
        wanted: String,
        /// The devices of the file (bounded).
        list: String,
    },
    /// The device does not take the modules asked for.
    #[error("{file}: device {device}: {source}")]
    Module {
        /// File name.
        file: String,
        /// Device type name.
        device: String,
        /// Why.
        #[source]
        source: Box<ModuleError>,
    },
}

/// `0x…` / `#x…` hex or decimal, as a `u32`.
fn number(t: &str) -> Option<u32> {
    let t = t.trim();
    match t
        .strip_prefix("0x")
        .or_else(|| t.strip_prefix("0X"))
        .or_else(|| t.strip_prefix("#x"))
        .or_else(|| t.strip_prefix("#X"))
    {
        Some(h) if !h.is_empty() && h.bytes().all(|b| b.is_ascii_hexdigit()) => {
            u32::from_str_radix(h, 16).ok()
        }
        Some(_) => None,
        None if !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit()) => t.parse().ok(),
        None => None,
    }
}

impl FromStr for Selector {
    type Err = SelectError;

    fn from_str(s: &str) -> Result<Selector, SelectError> {
        let syntax = |why: &str| SelectError::Syntax {
            text: s.to_string(),
            why: why.to_string(),
        };
        let mut parts = s.split('+');
        let dev = parts.next().unwrap_or("").trim();
        let modules = parts
            .map(|m| {
                let m = m.trim();
                if m.is_empty() {
                    ModuleChoice::Default
                } else if let Some(i) = number(m) {
                    ModuleChoice::Ident(i)
                } else {
                    ModuleChoice::Name(m.to_string())
                }
            })
            .collect();
        if dev.is_empty() {
            return Err(syntax("no device (a type name, a product code or @N)"));
        }
        let device = if let Some(n) = dev.strip_prefix('@') {
            match n.trim().parse::<usize>() {
                Ok(n) if n >= 1 => DeviceSelector::Position(n),
                _ => {
                    return Err(syntax(
                        "@N needs a position 1, 2, … (as `esi list` numbers)",
                    ))
                }
            }
        } else {
            // a tail that is no number belongs to the type name (`A/B`)
            let (what, revision) = match dev.rsplit_once('/') {
                Some((what, rev)) => match number(rev) {
                    Some(r) => (what.trim(), Some(r)),
                    None => (dev, None),
                },
                None => (dev, None),
            };
            if what.is_empty() {
                return Err(syntax("no type name or product code before the revision"));
            }
            match number(what) {
                Some(code) => DeviceSelector::Product { code, revision },
                None => DeviceSelector::Type {
                    name: what.to_string(),
                    revision,
                },
            }
        };
        Ok(Selector {
            device,
            modules,
            text: dev.to_string(),
        })
    }
}

/// `FILE.xml#SEL` → (`FILE.xml`, `Some("SEL")`); without a `#`: (spec, `None`). See the module
/// docs for where it splits.
pub fn split_spec(spec: &str) -> (&str, Option<&str>) {
    let lower = spec.to_ascii_lowercase();
    let at = lower
        .match_indices(".xml#")
        .next()
        .map(|(i, _)| i + 4)
        .or_else(|| spec.find('#'));
    match at {
        Some(i) => (&spec[..i], Some(&spec[i + 1..])),
        None => (spec, None),
    }
}

/// A device chosen from a file and resolved with its modules: what every consumer (emulator,
/// SII builder, drive definition) uses. Derefs to the [`Device`].
#[derive(Debug, Clone, PartialEq)]
pub struct Resolved {
    /// Position in the file (1-based, as `@N`).
    pub position: usize,
    /// The device, with its modules' PDOs and objects ([`Device::resolve`]).
    pub device: Device,
    /// What the choice involved that the user should know (several matches, the one picked).
    pub notes: Vec<String>,
}

impl std::ops::Deref for Resolved {
    type Target = Device;
    fn deref(&self) -> &Device {
        &self.device
    }
}

/// Devices listed in a message at most.
const LISTED: usize = 24;

/// `@1 0x00010402 (FP-CIA402-SERVO) revision 0x00010000, …` (bounded).
fn list(file: &EsiFile) -> String {
    if file.devices.is_empty() {
        return "no devices".to_string();
    }
    let mut v: Vec<String> = file
        .devices
        .iter()
        .take(LISTED)
        .enumerate()
        .map(|(i, d)| describe(i + 1, d))
        .collect();
    if file.devices.len() > LISTED {
        v.push(format!(
            "… {} more (fieldprobe esi list {})",
            file.devices.len() - LISTED,
            file.file
        ));
    }
    v.join(", ")
}

fn describe(position: usize, d: &Device) -> String {
    format!(
        "@{position} 0x{:08X} ({}) revision 0x{:08X}",
        d.product_code, d.type_name, d.revision_no
    )
}

impl EsiFile {
    /// The device `sel` names (position 1-based, the device as the file describes it, notes);
    /// see the module docs. Modules are not resolved here ([`resolve`] does both).
    pub fn select(
        &self,
        sel: Option<&Selector>,
    ) -> Result<(usize, &Device, Vec<String>), SelectError> {
        let Some(sel) = sel else {
            return match self.devices.as_slice() {
                [one] => Ok((1, one, Vec::new())),
                [] => Err(SelectError::NoDevices {
                    file: self.file.clone(),
                }),
                _ => Err(SelectError::Several {
                    file: self.file.clone(),
                    count: self.devices.len(),
                    list: list(self),
                }),
            };
        };
        let no_match = |wanted: String| SelectError::NoMatch {
            file: self.file.clone(),
            wanted,
            list: list(self),
        };
        let rev_ok = |d: &Device, r: Option<u32>| r.is_none_or(|r| d.revision_no == r);
        let rev_text = |r: Option<u32>| {
            r.map(|r| format!(" and revision 0x{r:08X}"))
                .unwrap_or_default()
        };
        let by_name = |name: &str, r: Option<u32>| -> Vec<usize> {
            let name = name.trim();
            let typed: Vec<usize> = (0..self.devices.len())
                .filter(|&i| {
                    let d = &self.devices[i];
                    d.type_name.trim().eq_ignore_ascii_case(name) && rev_ok(d, r)
                })
                .collect();
            if !typed.is_empty() {
                return typed;
            }
            (0..self.devices.len())
                .filter(|&i| {
                    let d = &self.devices[i];
                    d.names
                        .iter()
                        .any(|n| n.text.trim().eq_ignore_ascii_case(name))
                        && rev_ok(d, r)
                })
                .collect()
        };
        let found: Vec<usize> = match &sel.device {
            DeviceSelector::Position(n) => {
                return match n.checked_sub(1).and_then(|i| self.devices.get(i)) {
                    Some(d) => Ok((*n, d, Vec::new())),
                    None => Err(no_match(format!(
                        "no device at position @{n} (the file has {})",
                        self.devices.len()
                    ))),
                };
            }
            DeviceSelector::Product { code, revision } => {
                let by_code: Vec<usize> = (0..self.devices.len())
                    .filter(|&i| {
                        let d = &self.devices[i];
                        d.product_code == *code && rev_ok(d, *revision)
                    })
                    .collect();
                let text = sel
                    .text
                    .rsplit_once('/')
                    .map_or(sel.text.as_str(), |(t, _)| t);
                let found = if by_code.is_empty() {
                    by_name(text, *revision)
                } else {
                    by_code
                };
                if found.is_empty() {
                    return Err(no_match(format!(
                        "no device with product code 0x{code:08X}{}",
                        rev_text(*revision)
                    )));
                }
                found
            }
            DeviceSelector::Type { name, revision } => {
                let found = by_name(name, *revision);
                if found.is_empty() {
                    return Err(no_match(format!(
                        "no device with type name {name}{}",
                        rev_text(*revision)
                    )));
                }
                found
            }
        };
        let best = found
            .iter()
            .copied()
            .max_by(|&a, &b| {
                // highest revision; among equal ones the first in the file
                self.devices[a]
                    .revision_no
                    .cmp(&self.devices[b].revision_no)
                    .then(b.cmp(&a))
            })
            .unwrap_or(found[0]);
        let mut notes = Vec::new();
        if found.len() > 1 {
            let all: Vec<String> = found
                .iter()
                .take(LISTED)
                .map(|&i| describe(i + 1, &self.devices[i]))
                .collect();
            let d = &self.devices[best];
            notes.push(format!(
                "{}#{sel}: {} devices match ({}); picked @{} {} revision 0x{:08X}, the highest \
                 revision (name a revision or a position to pick another)",
                self.file,
                found.len(),
                all.join(", "),
                best + 1,
                d.type_name,
                d.revision_no
            ));
        }
        Ok((best + 1, &self.devices[best], notes))
    }
}

/// Choose the device `sel` names ([`EsiFile::select`]) and resolve it with the modules `sel`
/// names, each remaining slot getting its default module ([`Device::resolve`]).
pub fn resolve(file: &EsiFile, sel: Option<&Selector>) -> Result<Resolved, SelectError> {
    let (position, device, mut notes) = file.select(sel)?;
    let choices = sel.map(|s| s.modules.as_slice()).unwrap_or(&[]);
    let device = device
        .resolve(choices)
        .map_err(|source| SelectError::Module {
            file: file.file.clone(),
            device: device.type_name.clone(),
            source: Box::new(source),
        })?;
    if let Some(plugged) = device.plugged.as_ref().filter(|p| !p.is_empty()) {
        let named = choices.len();
        let defaults: Vec<String> = plugged
            .iter()
            .skip(named)
            .map(|p| {
                format!(
                    "slot {} ({}): #x{:X} {}",
                    p.slot, p.slot_name, p.ident, p.type_name
                )
            })
            .collect();
        if !defaults.is_empty() {
            notes.push(format!(
                "{}: device {}: default module(s) {}",
                file.file,
                device.type_name,
                defaults.join(", ")
            ));
        }
    }
    Ok(Resolved {
        position,
        device,
        notes,
    })
}
