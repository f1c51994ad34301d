//! The PDO mapping the master writes in PRE-OPERATIONAL, fitted to what the node offers
//! (issue 19; the CANopen side of [`crate::link::ethercat`]'s `pdo_fit`).
//!
//! CiA 301 has no SDO information service, so before the mapping of an axis's drive definition
//! (`drives/*.toml` `[rxpdo]` / `[txpdo]`) is written the master asks the node for every
//! entry with an SDO upload ([`Offer::from_upload`]): abort 0x0602_0000 / 0x0609_0011 — the
//! node does not have the object; data of another length than the drive file's type — another
//! bit length; any other answer — the object is there (a write-only object answers 0x0601_0001).
//! Whether it may be mapped the node says when the mapping is written: an entry refused with
//! 0x0604_0041 (or 0x0602_0000 / 0x0609_0011) is not offered either ([`is_mapping_refusal`]),
//! and the mapping is fitted again and written from the start.
//!
//! * A **required** object the node lacks (anything but the touch probe) refuses the start-up:
//!   error [`ids::CANOPEN_PDO_OBJECTS_MISSING`] names the node, the drive and each object with
//!   the reason.
//! * The **touch-probe** objects ([`is_touch_probe`]) are optional: when the node lacks one,
//!   it is left out of the mapping (all of them when 0x60B8 or 0x60B9 is missing: the latch
//!   needs both), the axis runs with that reduced definition and so has no drive latch, and
//!   warning [`ids::CANOPEN_NO_DRIVE_LATCH`] says so (seed 004 §7 lists what measures without
//!   one: PLC sampling, PLC_TIMESTAMP with a timestamp input terminal, an external latch).
//!
//! # The node's PDOs (issue 25)
//!
//! The master also asks the node how many PDOs it has and how many entries each takes
//! ([`PdoSlots`]: SDO uploads of the communication parameters 0x1400 + k / 0x1800 + k sub 1
//! and of the mapping parameters' sub-indices; abort 0x0602_0000 / 0x0609_0011 = not there —
//! the master has only the bus, not the EDS) and fits its layout into them ([`plan`]):
//! fewer entries per PDO, several PDOs where the node has them, one RPDO for everything
//! cyclic where it has one. A CAN frame carries 8 bytes: where the set-points do not fit, the
//! mode of operation 0x6060 — which need not be cyclic, CSP is set once — leaves the RPDOs and
//! the master writes it (8) by SDO in PRE-OPERATIONAL, as it does for any definition that does
//! not map it (CiA 402 §6.2 needs 0x6060 = 8 for CSP either way). What still does not fit is
//! error [`ids::CANOPEN_PDO_CAPACITY`] naming node, drive, what the node offers and the objects
//! left without a PDO.
//!
//! A refusal while the mapping is written says whose fault it is ([`Refusal`]): abort
//! 0x0609_0011 on mapping sub-index *j* — the mapping parameter has no sub-index *j*, it takes
//! *j* − 1 entries (the master fits again with that); 0x0604_0041 — the object cannot be mapped;
//! 0x0602_0000 — the object is not in the dictionary.

use std::sync::Arc;

use crate::bus::canopen::pdo::{plan_layout_in, Direction, Pdo, PdoSlots};
use crate::drive::catalogue::DriveDefinition;
use crate::drive::pdo::{is_touch_probe, DataType};
use crate::link::LinkError;
use crate::messages::{ids, CncMessage};

/// CiA 301 abort: object does not exist in the object dictionary.
const NO_OBJECT: u32 = 0x0602_0000;
/// CiA 301 abort: sub-index does not exist.
const NO_SUB_INDEX: u32 = 0x0609_0011;
/// CiA 301 abort: object cannot be mapped to the PDO.
const NOT_MAPPABLE: u32 = 0x0604_0041;

/// An object of the drive definition the node does not offer, and why (in words).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Lacking {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Why, e.g. `not in its object dictionary (SDO abort 0x06020000)`.
    pub why: String,
}

/// What an SDO upload of a mapped object says about it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Offer {
    /// The node has it (or refused the upload for another reason: the mapping write decides).
    Present,
    /// The node does not offer it: the reason.
    Lacking(String),
}

impl Offer {
    /// The answer to an upload of an object the drive file maps with type `ty`: the data
    /// (`Ok`) or the CiA 301 abort code (`Err`).
    pub fn from_upload(answer: Result<&[u8], u32>, ty: DataType) -> Offer {
        match answer {
            Ok(data) if data.len() != ty.size() => Offer::Lacking(format!(
                "{} bits on the node, {} in the drive file",
                8 * data.len(),
                8 * ty.size()
            )),
            Ok(_) => Offer::Present,
            Err(code) if code == NO_OBJECT || code == NO_SUB_INDEX => Offer::Lacking(format!(
                "not in its object dictionary (SDO abort {code:#010x})"
            )),
            Err(_) => Offer::Present,
        }
    }
}

/// Is `code`, the answer to writing mapping entry `value` (index << 16 | sub << 8 | bits), the
/// node refusing that object in a PDO? The object and the reason. (0x0609_0011 is about the
/// mapping parameter's sub-index, not the object: [`refusal`].)
pub fn is_mapping_refusal(code: u32, value: u32, rx: bool) -> Option<Lacking> {
    let (index, sub) = ((value >> 16) as u16, (value >> 8) as u8);
    let why = match code {
        NOT_MAPPABLE => format!(
            "not mappable into {} (SDO abort {code:#010x})",
            if rx { "an RPDO" } else { "a TPDO" }
        ),
        NO_OBJECT => format!("not in its object dictionary (SDO abort {code:#010x})"),
        _ => return None,
    };
    Some(Lacking { index, sub, why })
}

/// Why the node refused a write of its PDO mapping (module documentation).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Refusal {
    /// The object of the entry: not mappable or not there ([`is_mapping_refusal`]).
    Object(Lacking),
    /// The mapping parameter of PDO `pdo` (0-based) of `direction` has no sub-index `sub`
    /// (abort 0x0609_0011): it takes `sub` − 1 entries.
    NoSubIndex {
        /// RPDO or TPDO.
        direction: Direction,
        /// PDO number, 0-based.
        pdo: u8,
        /// The sub-index refused.
        sub: u8,
    },
}

/// The refusal `code` of writing `value` to mapping parameter `index` (0x1600 … 0x17FF,
/// 0x1A00 … 0x1BFF) sub-index `sub` ≥ 1, if it is one the master fits around.
pub fn refusal(code: u32, index: u16, sub: u8, value: u32) -> Option<Refusal> {
    let rx = index < 0x1800;
    if code == NO_SUB_INDEX {
        let (direction, base) = if rx {
            (Direction::Rx, 0x1600)
        } else {
            (Direction::Tx, 0x1A00)
        };
        return Some(Refusal::NoSubIndex {
            direction,
            pdo: u8::try_from(index.checked_sub(base)?).ok()?,
            sub,
        });
    }
    is_mapping_refusal(code, value, rx).map(Refusal::Object)
}

/// The PDOs of one node, per direction ([`PdoSlots`], asked by SDO at start-up).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NodePdos {
    /// RPDOs.
    pub rx: PdoSlots,
    /// TPDOs.
    pub tx: PdoSlots,
}

impl NodePdos {
    /// The slots of `direction`.
    pub fn of(&mut self, direction: Direction) -> &mut PdoSlots {
        match direction {
            Direction::Rx => &mut self.rx,
            Direction::Tx => &mut self.tx,
        }
    }
}

/// The answer to an SDO upload while asking a node for its PDOs: present (the data or a
/// refusal other than "not there"), or not there (abort 0x0602_0000 / 0x0609_0011).
pub fn is_there(answer: &Result<Vec<u8>, u32>) -> bool {
    !matches!(answer, Err(c) if *c == NO_OBJECT || *c == NO_SUB_INDEX)
}

/// The master's PDOs of a definition fitted into the node's PDOs ([`plan`]).
#[derive(Debug, Clone)]
pub struct Planned {
    /// The definition mapped: `def`, or `def` without 0x6060 when the master writes it by SDO
    /// instead.
    pub def: Arc<DriveDefinition>,
    /// RPDOs.
    pub rx: Vec<Pdo>,
    /// TPDOs.
    pub tx: Vec<Pdo>,
    /// 0x6060 is in no RPDO: the master writes it by SDO in PRE-OPERATIONAL.
    pub mode_by_sdo: bool,
}

/// Fit `def`'s process data into the PDOs `pdos` of node `node` (module documentation): the
/// PDOs, or error [`ids::CANOPEN_PDO_CAPACITY`].
pub fn plan(def: &Arc<DriveDefinition>, node: u8, pdos: &NodePdos) -> Result<Planned, LinkError> {
    const MODE: (u16, u8) = (0x6060, 0);
    let mut def = def.clone();
    let rx = match plan_layout_in(&def.rxpdo, Direction::Rx, node, &pdos.rx) {
        Ok(rx) => rx,
        Err(first) if def.rxpdo.contains(MODE.0, MODE.1) => {
            let mut without = (*def).clone();
            without.rxpdo = def.rxpdo.without(|i, s| (i, s) == MODE);
            without.rxpdo_defaults.retain(|d| (d.index, d.sub) != MODE);
            match plan_layout_in(&without.rxpdo, Direction::Rx, node, &pdos.rx) {
                Ok(rx) => {
                    tracing::info!(target: "fieldprobe::link::canopen", node,
                        "node {node}: {first}; 0x6060:00 modes of operation leaves the RPDOs \
                         and is written by SDO");
                    def = Arc::new(without);
                    rx
                }
                Err(e) => {
                    return Err(capacity_error(
                        node,
                        &def,
                        &format!(
                            "{e}, even with 0x6060:00 modes of operation out of the RPDOs \
                             (written by SDO)"
                        ),
                    ))
                }
            }
        }
        Err(e) => return Err(capacity_error(node, &def, &e.to_string())),
    };
    let tx = plan_layout_in(&def.txpdo, Direction::Tx, node, &pdos.tx)
        .map_err(|e| capacity_error(node, &def, &e.to_string()))?;
    let mode_by_sdo = !def.rxpdo.contains(MODE.0, MODE.1);
    Ok(Planned {
        def,
        rx,
        tx,
        mode_by_sdo,
    })
}

fn capacity_error(node: u8, def: &DriveDefinition, why: &str) -> LinkError {
    LinkError::Refused(CncMessage::error(
        ids::CANOPEN_PDO_CAPACITY,
        format!(
            "node {node}: the process data of drive '{}' ({}) do not fit the node's PDOs: {why}",
            def.name, def.file
        ),
    ))
}

/// The definition to map for node `node` whose drive definition is `def`, given what the node
/// lacks (see the module documentation): `def` itself when nothing is lacking; `def` without
/// the touch-probe objects and warning [`ids::CANOPEN_NO_DRIVE_LATCH`] when only those are
/// lacking; error [`ids::CANOPEN_PDO_OBJECTS_MISSING`] when a required object is lacking.
pub fn fit(
    def: &Arc<DriveDefinition>,
    node: u8,
    lacking: &[Lacking],
) -> Result<(Arc<DriveDefinition>, Option<CncMessage>), LinkError> {
    if lacking.is_empty() {
        return Ok((def.clone(), None));
    }
    let required: Vec<String> = lacking
        .iter()
        .filter(|l| !is_touch_probe(l.index))
        .map(|l| format!("{:#06X}:{:02X} ({})", l.index, l.sub, l.why))
        .collect();
    if !required.is_empty() {
        return Err(LinkError::Refused(CncMessage::error(
            ids::CANOPEN_PDO_OBJECTS_MISSING,
            format!(
                "node {node}: drive '{}' ({}) maps objects the node does not offer: {}",
                def.name,
                def.file,
                required.join(", ")
            ),
        )));
    }
    let latch_gone = lacking
        .iter()
        .any(|l| (l.index, l.sub) == (0x60B8, 0) || (l.index, l.sub) == (0x60B9, 0));
    let drop = |index: u16, sub: u8| {
        (latch_gone && is_touch_probe(index))
            || lacking.iter().any(|l| (l.index, l.sub) == (index, sub))
    };
    let mut fitted = (**def).clone();
    fitted.rxpdo = def.rxpdo.without(drop);
    fitted.txpdo = def.txpdo.without(drop);
    fitted.rxpdo_defaults.retain(|d| !drop(d.index, d.sub));
    // "0x60B8:00, 0x60B9:00 (not in its object dictionary …)": objects grouped by reason.
    let mut reasons: Vec<&str> = Vec::new();
    for l in lacking {
        if !reasons.contains(&l.why.as_str()) {
            reasons.push(&l.why);
        }
    }
    let listed: Vec<String> = reasons
        .iter()
        .map(|why| {
            let objects: Vec<String> = lacking
                .iter()
                .filter(|l| l.why == *why)
                .map(|l| format!("{:#06X}:{:02X}", l.index, l.sub))
                .collect();
            format!("{} ({why})", objects.join(", "))
        })
        .collect();
    let text = if latch_gone {
        format!(
            "node {node} has no touch probe for drive '{}': {}; the PDO mapping leaves the \
             touch-probe objects out and the axis has no drive latch (measure with PLC, \
             PLC_TIMESTAMP and a timestamp input terminal, or an external latch, seed 004 §7)",
            def.name,
            listed.join(", ")
        )
    } else {
        format!(
            "node {node} lacks touch-probe objects of drive '{}': {}; the PDO mapping leaves \
             them out",
            def.name,
            listed.join(", ")
        )
    };
    Ok((
        Arc::new(fitted),
        Some(CncMessage::warning(ids::CANOPEN_NO_DRIVE_LATCH, text)),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::catalogue;

    fn generic() -> Arc<DriveDefinition> {
        Arc::new(catalogue::load("cia402-generic").unwrap())
    }

    #[test]
    fn upload_answers_say_what_the_node_offers() {
        assert_eq!(
            Offer::from_upload(Ok(&[0, 0]), DataType::U16),
            Offer::Present
        );
        assert_eq!(
            Offer::from_upload(Ok(&[0, 0, 0, 0]), DataType::U16),
            Offer::Lacking("32 bits on the node, 16 in the drive file".into())
        );
        assert_eq!(
            Offer::from_upload(Err(0x0601_0001), DataType::U16),
            Offer::Present
        );
        assert!(matches!(
            Offer::from_upload(Err(0x0602_0000), DataType::U16),
            Offer::Lacking(w) if w.contains("0x06020000")
        ));
    }

    #[test]
    fn a_missing_touch_probe_leaves_every_touch_probe_object_out_with_900504() {
        let def = generic();
        let lacking = [Lacking {
            index: 0x60B8,
            sub: 0,
            why: "not in its object dictionary (SDO abort 0x06020000)".into(),
        }];
        let (fitted, warning) = fit(&def, 7, &lacking).unwrap();
        let w = warning.unwrap();
        assert_eq!(w.id, 900504);
        assert!(w.text.contains("node 7 has no touch probe"), "{}", w.text);
        assert!(
            w.text.contains("0x60B8:00 (not in its object dictionary"),
            "{}",
            w.text
        );
        for e in fitted.rxpdo.entries().iter().chain(fitted.txpdo.entries()) {
            assert!(!is_touch_probe(e.index), "{:#x} left in", e.index);
        }
        // The rest stays in its order: 0x6040, 0x607A, 0x6060 / 0x6041, 0x6064, 0x60F4 …
        let rx: Vec<u16> = fitted.rxpdo.entries().iter().map(|e| e.index).collect();
        assert_eq!(rx, [0x6040, 0x607A, 0x6060]);
        let tx: Vec<u16> = fitted.txpdo.entries().iter().map(|e| e.index).collect();
        assert_eq!(tx, [0x6041, 0x6064, 0x60F4, 0x6061, 0x6077]);
    }

    #[test]
    fn a_missing_required_object_is_error_900505_naming_it() {
        let def = generic();
        let lacking = [
            Lacking {
                index: 0x607A,
                sub: 0,
                why: "not mappable into an RPDO (SDO abort 0x06040041)".into(),
            },
            Lacking {
                index: 0x60BA,
                sub: 0,
                why: "x".into(),
            },
        ];
        let Err(LinkError::Refused(m)) = fit(&def, 3, &lacking) else {
            panic!("a required object is missing");
        };
        assert_eq!(m.id, 900505);
        assert!(m.text.contains("node 3"), "{}", m.text);
        assert!(m.text.contains("'cia402-generic'"), "{}", m.text);
        assert!(
            m.text
                .contains("0x607A:00 (not mappable into an RPDO (SDO abort 0x06040041))"),
            "{}",
            m.text
        );
        assert!(!m.text.contains("0x60BA"), "{}", m.text);
    }

    #[test]
    fn a_refused_mapping_sub_index_is_the_capacity_not_the_object() {
        // Writing 0x607A into 0x1600:02 refused with 0x06090011: 0x1600 has no sub-index 2.
        assert_eq!(
            refusal(0x0609_0011, 0x1600, 2, 0x607A_0020),
            Some(Refusal::NoSubIndex {
                direction: Direction::Rx,
                pdo: 0,
                sub: 2
            })
        );
        assert_eq!(
            refusal(0x0609_0011, 0x1A03, 5, 0x6077_0010),
            Some(Refusal::NoSubIndex {
                direction: Direction::Tx,
                pdo: 3,
                sub: 5
            })
        );
        // 0x06040041: the object 0x607A cannot be mapped.
        let Some(Refusal::Object(l)) = refusal(0x0604_0041, 0x1600, 2, 0x607A_0020) else {
            panic!("object refusal");
        };
        assert_eq!((l.index, l.sub), (0x607A, 0));
        assert!(l
            .why
            .contains("not mappable into an RPDO (SDO abort 0x06040041)"));
        assert_eq!(refusal(0x0800_0000, 0x1600, 2, 0x607A_0020), None);
    }

    fn slots(rx: [u8; 4], tx: [u8; 4]) -> NodePdos {
        NodePdos {
            rx: PdoSlots { entries: rx },
            tx: PdoSlots { entries: tx },
        }
    }

    #[test]
    fn one_rpdo_with_the_touch_probe_sends_the_mode_of_operation_by_sdo() {
        // The generic drive: 0x6040 2 + 0x607A 4 + 0x60B8 2 = 8 bytes, 0x6060 1 more.
        let def = generic();
        let p = plan(&def, 2, &slots([8, 0, 0, 0], [8; 4])).unwrap();
        assert!(p.mode_by_sdo);
        assert_eq!(p.rx.len(), 1);
        let rx: Vec<u16> = p.rx[0].mapped.iter().map(|m| m.index).collect();
        assert_eq!(rx, [0x6040, 0x607A, 0x60B8]);
        assert!(!p.def.rxpdo.contains(0x6060, 0));
        // With the full connection set nothing moves.
        let p = plan(&def, 2, &slots([8; 4], [8; 4])).unwrap();
        assert!(!p.mode_by_sdo && Arc::ptr_eq(&p.def, &def));
    }

    #[test]
    fn what_does_not_fit_is_900506_naming_node_drive_and_objects() {
        let def = generic();
        let Err(LinkError::Refused(m)) = plan(&def, 4, &slots([2, 0, 0, 0], [8; 4])) else {
            panic!("2 entries cannot carry 0x6040, 0x607A and 0x60B8");
        };
        assert_eq!(m.id, 900506);
        for want in [
            "node 4",
            "'cia402-generic'",
            "1 RPDO (0x1600: 2 entries)",
            "no PDO is left for 0x60B8:00 (2 bytes)",
            "even with 0x6060:00 modes of operation out of the RPDOs",
        ] {
            assert!(m.text.contains(want), "{want:?} in {}", m.text);
        }
        let Err(LinkError::Refused(m)) = plan(&def, 4, &slots([8; 4], [1, 1, 0, 0])) else {
            panic!("2 TPDOs of 1 entry cannot carry the generic drive's inputs");
        };
        assert!(
            m.text.contains("2 TPDOs (0x1A00 … 0x1A01: 1, 1 entries)"),
            "{}",
            m.text
        );
    }

    #[test]
    fn mapping_refusals_name_the_object() {
        let l = is_mapping_refusal(0x0604_0041, 0x605A_0010, true).unwrap();
        assert_eq!((l.index, l.sub), (0x605A, 0));
        assert!(l.why.contains("an RPDO"));
        assert!(is_mapping_refusal(0x0609_0030, 0x605A_0010, true).is_none());
    }
}
