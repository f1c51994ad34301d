//! `ethercat-emu`: the in-process emulated segment the link's frames go through (feature
//! `sim`). The segment is built from the machine ([`emulated_segment`]); the link reaches it for
//! the plant, the drive models and the fault knobs.

use std::time::Duration;

use super::terminals::{self, TerminalSpec};
use super::{embedded, esi_for, EthercatLink, EthercatSpec, COUPLER_ESI, MAX_SUBDEVICES};
use crate::drive::catalogue::Profile;
use crate::esi;
use crate::link::LinkError;
use crate::sim::esc::device::emulated_drive;
use crate::sim::esc::segment::Segment;
use crate::sim::esc::{Esc, EscConfig, NullApp};
use crate::sim::plant::Plant;
use crate::sim::world::World;

/// The CiA 402 touch-probe objects: 0x60B8 function, 0x60B9 status, 0x60BA – 0x60BD values.
const TOUCH_PROBE: std::ops::RangeInclusive<u16> = 0x60B8..=0x60BD;

/// The servo ESI device as it is without the touch-probe option: the same identity, its
/// default PDOs and ESI dictionary without the touch-probe objects — what the emulator plays
/// for a CiA 402 drive definition without touch probe (many real drives have none; issue 19),
/// so that its PDO mapping matches the definition's.
fn without_touch_probe(device: &esi::Device) -> esi::Device {
    let mut d = device.clone();
    for p in d.rx_pdos.iter_mut().chain(d.tx_pdos.iter_mut()) {
        p.entries.retain(|e| !TOUCH_PROBE.contains(&e.index));
    }
    if let Some(dict) = d.profile.as_mut().and_then(|p| p.dictionary.as_mut()) {
        dict.objects.retain(|o| !TOUCH_PROBE.contains(&o.index));
    }
    d
}

/// Forwarding delay between neighbouring emulated devices.
const HOP_DELAY_NS: u64 = 500;

/// The emulated segment for `spec`: a coupler, then the machine's SubDevices in ring order
/// ([`terminals::ring_order`]) — one drive per axis (the ESI of its family, the model of its
/// drive definition) and its terminals (each played as
/// [`emulated_terminal`](crate::sim::esc::terminal::emulated_terminal) plays it) — then the
/// extra devices, with an empty plant, synchronised at SYNC0. A CiA 402 drive definition without
/// touch probe gets the servo without it (its ESI device without 0x60B8 … 0x60BD).
pub fn emulated_segment(spec: &EthercatSpec) -> Result<Segment, LinkError> {
    let other = |m: String| LinkError::Other(m);
    let coupler_esi = embedded(COUPLER_ESI, "esi/fieldprobe-ek1100.xml")?;
    let coupler_dev = coupler_esi
        .devices
        .first()
        .ok_or_else(|| other("coupler ESI has no device".into()))?;
    let content = esi::to_sii::sii_from_device(coupler_esi, coupler_dev)
        .map_err(|e| other(format!("coupler SII: {e}")))?;
    let image =
        esi::sii::encode_padded(&content).map_err(|e| other(format!("coupler SII: {e}")))?;
    let mut escs = vec![Esc::new(EscConfig::from_sii(image), Box::new(NullApp))];
    let cycle = Duration::from_nanos(spec.cycle.0.max(1));
    let terminal_esc = |t: &TerminalSpec| -> Result<Esc, LinkError> {
        let device = t
            .device()
            .ok_or_else(|| other(format!("terminal {}: the ESI has no device", t.name)))?;
        crate::sim::esc::terminal::emulated_terminal(&t.esi, device)
            .map_err(|e| other(format!("terminal {} ({}): {e}", t.name, t.source)))
    };
    for d in terminals::ring_order(spec.drives.len(), &spec.terminals) {
        let k = match d {
            terminals::Declared::Axis(k) => k,
            terminals::Declared::Terminal(k) => {
                if let Some(t) = spec.terminals.get(k) {
                    escs.push(terminal_esc(t)?);
                }
                continue;
            }
        };
        let Some(def) = spec.drives.get(k) else {
            continue;
        };
        let axis = k;
        if let (Some(esi), Some(id)) = (&def.esi, def.identity) {
            escs.push(vendor_drive(axis, def, esi, id, cycle)?);
            continue;
        }
        let text = esi_for(def).ok_or_else(|| {
            other(format!(
                "axis {axis}: drive '{}' is a {} drive; the EtherCAT emulator plays CiA 402 and SERCOS drives and EL5101 terminals only",
                def.name,
                def.profile.name()
            ))
        })?;
        let file = embedded(text, "embedded ESI")?;
        let device = file
            .devices
            .first()
            .ok_or_else(|| other("ESI has no device".into()))?;
        let bare;
        let device = if def.profile == Profile::Cia402 && !def.has_drive_latch() {
            bare = without_touch_probe(device);
            &bare
        } else {
            device
        };
        let esc = emulated_drive(file, device, def, cycle)
            .map_err(|e| other(format!("axis {axis}, drive '{}': {e}", def.name)))?;
        escs.push(esc);
    }
    for t in &spec.emulated_extra {
        escs.push(terminal_esc(t)?);
    }
    if escs.len() > MAX_SUBDEVICES {
        return Err(other(format!(
            "the emulated segment would have {} SubDevices; the link holds at most {MAX_SUBDEVICES}",
            escs.len()
        )));
    }
    let mut seg = Segment::new(escs, HOP_DELAY_NS);
    seg.set_world(World::new(Plant::new()), spec.cycle);
    Ok(seg)
}

/// The vendor device of a drive definition with `[device] esi` (`drive from-esi`): the device
/// of that ESI with the definition's identity (product code, and revision where given),
/// played as [`emulated_vendor_drive`](crate::sim::esc::vendor::emulated_vendor_drive) plays it,
/// with the built-in `cia402-generic` model under the definition's `[model]`, `[probe]` and
/// scaling.
fn vendor_drive(
    axis: usize,
    def: &crate::drive::catalogue::DriveDefinition,
    esi_path: &str,
    id: crate::drive::catalogue::DeviceIdentity,
    cycle: Duration,
) -> Result<Esc, LinkError> {
    let other = |m: String| LinkError::Other(format!("axis {axis}, drive '{}': {m}", def.name));
    // `FILE.xml#SEL`: the device (and its modules) the selector names; without one, the
    // device with the definition's identity, each slot with its default module.
    let (file_part, sel) = match esi::split_spec(esi_path) {
        (f, Some(sel)) if !std::path::Path::new(esi_path).exists() => (f, Some(sel)),
        _ => (esi_path, None),
    };
    let given = std::path::Path::new(file_part);
    let beside = std::path::Path::new(&def.file)
        .parent()
        .map(|d| d.join(given))
        .filter(|p| !given.is_absolute() && p.exists());
    let path = match beside {
        Some(p) if !given.exists() => p,
        _ => given.to_path_buf(),
    };
    let file = esi::load(&path).map_err(|e| other(format!("[device] esi: {e}")))?;
    let device = match sel {
        Some(sel) => {
            let sel: esi::Selector = sel
                .parse()
                .map_err(|e| other(format!("[device] esi {esi_path}: {e}")))?;
            esi::resolve(&file, Some(&sel))
                .map_err(|e| other(format!("[device] esi {esi_path}: {e}")))?
                .device
        }
        None => file
            .device(id.product_code, id.revision.unwrap_or(u32::MAX))
            .or_else(|| file.device_by_product(id.product_code))
            .ok_or_else(|| {
                other(format!(
                    "[device] esi {}: no device with product code {:#010x}",
                    path.display(),
                    id.product_code
                ))
            })?
            // A modular device with the default module in every slot.
            .resolve(&[])
            .map_err(|e| other(format!("[device] esi {}: {e}", path.display())))?,
    };
    if device.product_code != id.product_code {
        return Err(other(format!(
            "[device] esi {esi_path} names product code {:#010x}, [device] product_code is {:#010x}",
            device.product_code, id.product_code
        )));
    }
    let device = &device;
    let mut base = crate::drive::catalogue::builtin("cia402-generic")
        .ok_or_else(|| other("the built-in cia402-generic drive is missing".into()))?;
    base.name = def.name.clone();
    base.scaling = def.scaling;
    base.model = def.model;
    base.probe = def.probe;
    crate::sim::esc::vendor::emulated_vendor_drive(&file, device, &base, cycle)
        .map(|v| v.esc)
        .map_err(|e| other(e.to_string()))
}

impl EthercatLink {
    /// The emulated segment (`ethercat-emu`), if any.
    pub fn segment(&self) -> Option<&Segment> {
        self.wire.segment()
    }

    /// The emulated segment, mutable (plant, fault knobs).
    pub fn segment_mut(&mut self) -> Option<&mut Segment> {
        self.wire.segment_mut()
    }
}
