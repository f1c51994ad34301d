//! SubDevices that are not axes: the I/O terminals a machine file names (`[[terminal]]`), and
//! the ones on the segment it does not name.
//!
//! The machine declares its SubDevices in ring order: the axes' drives in axis order, each
//! terminal where its `[[terminal]]` table stands among the `[[axis]]` tables of the file
//! ([`TerminalSpec::after_axes`]; [`ring_order`]). Each is found on the bus as an axis always
//! was: the next SubDevice in ring order, after the previous declared one's, with the vendor id
//! and product code of its ESI device ([`match_ring`]). Every SubDevice no declared one took is
//! *not named*: ethercrab takes it to OP with its default process data like the others, and the
//! link lists it at start-up (a real segment always carries more than the drives: couplers,
//! power feeds, spare terminals).
//!
//! The ESI of a terminal is one of the files the link embeds ([`EMBEDDED_ESI`], by name,
//! with or without `esi/` and `.xml`) or an ESI file; on `ethercat-emu` the emulator plays it
//! (`crate::sim::esc::terminal::emulated_terminal`, feature `sim`).

use std::path::Path;
use std::sync::Arc;

use crate::esi::{self, Device, EsiFile};

/// ESI of the emulated EL1252-kind timestamp input (embedded).
pub const EL1252_ESI: &str = include_str!("../../../esi/fieldprobe-el1252.xml");

/// The ESI files the link embeds, by name (`esi/<name>.xml`).
pub const EMBEDDED_ESI: [(&str, &str); 5] = [
    ("fieldprobe-ek1100", super::COUPLER_ESI),
    ("fieldprobe-el1252", EL1252_ESI),
    ("fieldprobe-el5101", super::EL5101_ESI),
    ("fieldprobe-cia402-servo", super::SERVO_ESI),
    ("fieldprobe-ax5000-sercos", super::SERCOS_ESI),
];

/// One SubDevice the machine names that is not an axis.
#[derive(Debug, Clone)]
pub struct TerminalSpec {
    /// Its name in the machine (`ENC1`), for messages and the library API.
    pub name: String,
    /// Where its ESI came from (`fieldprobe-el5101`, or the file).
    pub source: String,
    /// The ESI file.
    pub esi: Arc<EsiFile>,
    /// The terminal: the file's device the reference selects (`FILE.xml#SEL`, the syntax of
    /// [`esi::select`]), with its modules resolved.
    pub device: Device,
    /// Where it stands in the ring: after this many of the machine's axes (their drives);
    /// `usize::MAX` (the default of [`Self::resolve`]): after all of them.
    pub after_axes: usize,
}

impl TerminalSpec {
    /// The terminal `name` with the ESI `reference`: an embedded name ([`EMBEDDED_ESI`]) or an
    /// ESI file, relative to `base` (the machine file's directory) unless absolute, optionally
    /// with a device selector (`FILE.xml#SEL`: type name, product code and revision, `@N`,
    /// `+MODULE`s); a file with several devices needs one.
    ///
    /// # Errors
    /// A file that cannot be read or parsed, or one without a device, in words naming both.
    pub fn resolve(name: &str, reference: &str, base: Option<&Path>) -> Result<Self, String> {
        let whole = reference;
        let (reference, selector) = match esi::split_spec(whole) {
            (file, Some(sel)) if !Path::new(whole).exists() => (file, Some(sel)),
            _ => (whole, None),
        };
        let key = reference
            .strip_prefix("esi/")
            .unwrap_or(reference)
            .trim_end_matches(".xml");
        let esi = match EMBEDDED_ESI.iter().find(|(n, _)| *n == key) {
            Some((n, text)) => super::embedded(text, &format!("esi/{n}.xml"))
                .map(|f| Arc::new(f.clone()))
                .map_err(|e| format!("terminal {name}: esi {reference}: {e}"))?,
            None => {
                let path = match base {
                    Some(b) if Path::new(reference).is_relative() => b.join(reference),
                    _ => Path::new(reference).to_path_buf(),
                };
                let file = esi::load(&path).map_err(|e| {
                    format!(
                        "terminal {name}: esi \"{reference}\": {e} (built in: {})",
                        embedded_names()
                    )
                })?;
                Arc::new(file)
            }
        };
        if esi.devices.is_empty() {
            return Err(format!(
                "terminal {name}: esi \"{reference}\" describes no device"
            ));
        }
        let sel: Option<esi::Selector> = selector
            .map(|s| s.parse())
            .transpose()
            .map_err(|e| format!("terminal {name}: esi \"{whole}\": {e}"))?;
        let device = esi::resolve(&esi, sel.as_ref())
            .map_err(|e| format!("terminal {name}: esi \"{whole}\": {e}"))?
            .device;
        Ok(TerminalSpec {
            name: name.to_string(),
            source: whole.to_string(),
            esi,
            device,
            after_axes: usize::MAX,
        })
    }

    /// The ESI device the reference selects.
    pub fn device(&self) -> Option<&Device> {
        Some(&self.device)
    }

    /// (vendor id, product code) the SubDevice on the bus must have.
    pub fn identity(&self) -> Option<(u32, u32)> {
        self.device().map(|d| (self.esi.vendor.id, d.product_code))
    }

    /// The ESI type name (`FP-EL5101`).
    pub fn type_name(&self) -> &str {
        self.device().map_or("?", |d| d.type_name.as_str())
    }
}

/// The embedded ESI names, comma separated.
pub fn embedded_names() -> String {
    EMBEDDED_ESI
        .iter()
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

/// What a SubDevice is to the machine.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Role {
    /// The drive of axis `index` (axis order).
    Axis {
        /// Axis index.
        index: usize,
        /// Its drive definition.
        drive: String,
    },
    /// Terminal `index` of the machine (its `[[terminal]]` order).
    Terminal {
        /// Terminal index.
        index: usize,
        /// Terminal name.
        name: String,
    },
    /// Not named in the machine file: in OP with its default process data.
    NotNamed,
}

/// One SubDevice of the segment as the link found it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BusDevice {
    /// Ring position (0 = next to the MainDevice).
    pub position: usize,
    /// Configured station address.
    pub address: u16,
    /// Vendor id.
    pub vendor: u32,
    /// Product code.
    pub product: u32,
    /// Name from the SII.
    pub name: String,
    /// What it is to the machine.
    pub role: Role,
    /// Output bytes in the process image.
    pub outputs: usize,
    /// Input bytes in the process image.
    pub inputs: usize,
}

/// One SubDevice the machine declares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Declared {
    /// The drive of axis `i`.
    Axis(usize),
    /// Terminal `k`.
    Terminal(usize),
}

/// The machine's SubDevices in ring order: the axes' drives in axis order, each terminal after
/// [`TerminalSpec::after_axes`] of them (terminals in their own order where several stand at
/// the same place).
pub fn ring_order(axes: usize, terminals: &[TerminalSpec]) -> Vec<Declared> {
    let mut out = Vec::with_capacity(axes + terminals.len());
    for i in 0..=axes {
        out.extend(
            terminals
                .iter()
                .enumerate()
                .filter(|(_, t)| t.after_axes.min(axes) == i)
                .map(|(k, _)| Declared::Terminal(k)),
        );
        if i < axes {
            out.push(Declared::Axis(i));
        }
    }
    out
}

/// Find the declared SubDevices on the bus: entry `j` (identity `wants[j]`, `None`: any
/// SubDevice) takes the next SubDevice in ring order after entry `j − 1`'s with that identity.
/// `subs` are (vendor, product) in ring order. Each entry's ring position, or the first entry
/// not found with the position its search began at.
pub fn match_ring(
    wants: &[Option<(u32, u32)>],
    subs: &[(u32, u32)],
) -> Result<Vec<usize>, (usize, usize)> {
    let mut next = 0usize;
    let mut out = Vec::with_capacity(wants.len());
    for (j, want) in wants.iter().enumerate() {
        let found = (next..subs.len()).find(|&i| want.is_none_or(|w| subs[i] == w));
        let Some(i) = found else {
            return Err((j, next));
        };
        next = i + 1;
        out.push(i);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `FILE.xml#SEL` picks the terminal's device; a selector matching nothing names the file's
    /// devices.
    #[test]
    fn a_selector_picks_the_device() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let t = TerminalSpec::resolve("E", "esi/fieldprobe-el5101.xml#@1", Some(dir)).unwrap();
        assert_eq!(t.type_name(), "FP-EL5101");
        let by_name =
            TerminalSpec::resolve("E", "esi/fieldprobe-el5101.xml#FP-EL5101", Some(dir)).unwrap();
        assert_eq!(by_name.identity(), t.identity());
        let e = TerminalSpec::resolve("E", "esi/fieldprobe-el5101.xml#@2", Some(dir)).unwrap_err();
        assert!(e.contains("terminal E") && e.contains("@1"), "{e}");
    }

    #[test]
    fn embedded_names_resolve_and_files_are_named_in_errors() {
        for r in [
            "fieldprobe-el5101",
            "esi/fieldprobe-el1252.xml",
            "fieldprobe-ek1100.xml",
        ] {
            let t = TerminalSpec::resolve("T", r, None).unwrap();
            assert!(t.identity().is_some(), "{r}");
        }
        let e = TerminalSpec::resolve("T9", "no-such-file.xml", Some(Path::new("/nonexistent")))
            .unwrap_err();
        assert!(
            e.contains("terminal T9") && e.contains("no-such-file.xml"),
            "{e}"
        );
        assert!(
            e.contains("fieldprobe-el5101"),
            "lists the built-in ones: {e}"
        );
    }

    #[test]
    fn declared_devices_are_found_in_ring_order() {
        let mut enc = TerminalSpec::resolve("E", "fieldprobe-el5101", None).unwrap();
        let ts = TerminalSpec::resolve("T", "fieldprobe-el1252", None).unwrap();
        let (e, t) = (enc.identity().unwrap(), ts.identity().unwrap());
        // Terminal E between axes 0 and 1, T after all axes.
        enc.after_axes = 1;
        let order = ring_order(2, &[enc, ts]);
        assert_eq!(
            order,
            vec![
                Declared::Axis(0),
                Declared::Terminal(0),
                Declared::Axis(1),
                Declared::Terminal(1)
            ]
        );
        let servo = (9, 9);
        // 0 coupler (not named), 1 servo, 2 enc, 3 servo, 4 enc (not named), 5 ts.
        let subs = [(1, 2), servo, e, servo, e, t];
        let wants = [Some(servo), Some(e), Some(servo), Some(t)];
        assert_eq!(match_ring(&wants, &subs), Ok(vec![1, 2, 3, 5]));
        // An axis drive the emulator does not describe takes the next SubDevice.
        assert_eq!(match_ring(&[None, Some(e)], &subs), Ok(vec![0, 2]));
        // Not found: entry 3 (T) searched from position 4 on... in a ring without it.
        assert_eq!(match_ring(&wants, &subs[..5]), Err((3, 4)));
    }
}
