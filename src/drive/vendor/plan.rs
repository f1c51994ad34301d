//! A vendor device's CiA 402 roles and the PDOs that carry them, as a drive definition states
//! them (`[roles]`, `[rxpdo]` / `[txpdo]` with `pdos`, `fixed`, `defaults`): the result of
//! `esi_plan::plan` for an ESI device, written by [`super::generate`].

use super::super::pdo::{self, EntrySpec, Role};

/// A device object (or the part of one) that plays a role.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Part {
    /// Index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Bit length.
    pub bits: u16,
    /// Its first bit within the CiA 402 value (0 for a whole object).
    pub at: u16,
}

/// One way the device offers a CiA 402 role (`esi_plan::role_sources` finds them in an ESI).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RoleSource {
    /// The CiA 402 object (0x6040 …).
    pub index: u16,
    /// Its sub-index.
    pub sub: u8,
    /// Master → drive.
    pub rx: bool,
    /// The device's objects; one for a whole object, several for a word of bits.
    pub parts: Vec<Part>,
    /// For a word of bits: its length (the CiA 402 type's).
    pub word: Option<u16>,
    /// How it was found, for notes and docs.
    pub how: &'static str,
    /// Mappable into a configurable PDO of its direction (dictionary `PdoMapping`; for a
    /// dictionary without any such flag: a PDO of that direction holds it). Fixed PDOs carry
    /// what they carry, whatever this says.
    pub mappable: bool,
    /// Writable by SDO (`Access` rw / wo), for a role that is set once (the mode).
    pub writable: bool,
}

impl RoleSource {
    /// The device object of a whole-object source (or the first part of a word).
    pub fn object(&self) -> (u16, u8) {
        self.parts.first().map_or((0, 0), |p| (p.index, p.sub))
    }

    /// The [`Role`] a drive file states for this source (`None`: the CiA 402 object itself).
    pub fn role(&self) -> Option<Role> {
        let (object, object_sub) = self.object();
        if self.word.is_none() && (object, object_sub) == (self.index, self.sub) {
            return None;
        }
        Some(Role {
            index: self.index,
            sub: self.sub,
            object,
            object_sub,
            bits: self.word,
        })
    }

    /// Does the device object `index:sub` play (a part of) this role?
    pub fn has(&self, index: u16, sub: u8) -> bool {
        self.parts.iter().any(|p| p.index == index && p.sub == sub)
    }
}

/// One direction of a [`Plan`]: what `[rxpdo]` / `[txpdo]` of a drive file say.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DirectionPlan {
    /// The PDOs, in assignment order.
    pub pdos: Vec<u16>,
    /// They are the device's fixed PDOs (assigned as they are).
    pub fixed: bool,
    /// The entries, in image order (gaps and bit fields included).
    pub entries: Vec<EntrySpec>,
    /// Values for outputs that are not roles (`[rxpdo] defaults`): (index, sub, value, why).
    pub defaults: Vec<(u16, u8, i64, String)>,
}

/// Where each role of a CiA 402 axis sits on the device, and the PDOs that carry them.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Plan {
    /// Master → drive.
    pub rx: DirectionPlan,
    /// Drive → master.
    pub tx: DirectionPlan,
    /// The sources used (mapped, or written by SDO: the mode of operation when it is in no
    /// PDO), one per role the device offers.
    pub used: Vec<RoleSource>,
    /// Roles the device offers but the chosen PDOs do not carry, and why.
    pub left_out: Vec<(u16, String)>,
    /// Notes for the user (interpretations, defaults written, PDOs chosen).
    pub notes: Vec<String>,
}

impl Plan {
    /// The `[roles]` of the definition.
    pub fn roles(&self) -> Vec<Role> {
        self.used.iter().filter_map(RoleSource::role).collect()
    }

    /// The source used for CiA 402 object `index`.
    pub fn source(&self, index: u16) -> Option<&RoleSource> {
        self.used.iter().find(|s| s.index == index)
    }
}

/// Required roles the device cannot carry: one phrase each.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}", .missing.join("; "))]
pub struct PlanError {
    /// `0x607A:00 target position: …`, one per missing role.
    pub missing: Vec<String>,
}

/// Check the touch probe across both directions: without the function (out), the status (in)
/// or any edge value, the probe roles are dropped from `used` (their objects stay in a fixed
/// PDO's entries, plain data then) and the entries of a configurable PDO lose them.
pub fn finish(p: &mut Plan) {
    let has = |i: u16| p.used.iter().any(|s| s.index == i);
    let complete = has(0x60B8) && has(0x60B9) && (0x60BA..=0x60BD).any(has);
    if complete {
        return;
    }
    let probe: Vec<RoleSource> = p
        .used
        .iter()
        .filter(|s| pdo::is_touch_probe(s.index))
        .cloned()
        .collect();
    if probe.is_empty() {
        return;
    }
    for s in &probe {
        p.left_out.push((
            s.index,
            "the device has no complete touch probe (function, status and an edge value)".into(),
        ));
    }
    p.used.retain(|s| !pdo::is_touch_probe(s.index));
    for d in [&mut p.rx, &mut p.tx] {
        if d.fixed {
            continue;
        }
        let mut kept = Vec::new();
        let mut skip_gap = false;
        for e in d.entries.drain(..) {
            let in_probe = probe.iter().any(|s| s.has(e.index, e.sub));
            if in_probe {
                skip_gap = true;
                continue;
            }
            if e.is_gap() && skip_gap {
                continue;
            }
            skip_gap = false;
            kept.push(e);
        }
        d.entries = kept;
    }
}
