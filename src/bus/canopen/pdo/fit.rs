//! The master's layout fitted into the PDOs a node offers (issue 25): how many RPDOs / TPDOs
//! the node has and how many entries each mapping parameter takes ([`PdoSlots`]), and the
//! layout of [`super::plan_layout`] packed into them ([`plan_layout_in`]).
//!
//! CiA 301 §7.5.2.36 / .38: mapping parameter 0x1600 + k / 0x1A00 + k holds the number of
//! mapped objects in sub-index 0 and one entry per sub-index 1 … n; a device has as many
//! sub-indices as it can map (the Faulhaber MCBL 300x: 4, the Demaclenko emecdrv5's TPDOs 6 or
//! 7, most 8). A PDO is one CAN frame: at most 8 bytes.
//!
//! Order of attempts, the first that fits is taken:
//! 1. cyclic and on-change PDOs apart ([`super::plan_layout`]);
//! 2. everything cyclic (fewer PDOs: one RPDO for all set-points where the node has one);
//!
//! each with at most as many entries per PDO as the PDO it goes into takes (tried with every
//! capacity the node's PDOs have, largest first). What fits in none of them is [`Unfit`].

use super::{build, first_fit_by, on_change_class, Direction, Pdo, Trigger, MAX_PDOS};
use crate::drive::pdo::PdoLayout;

/// Entries a PDO takes at most when every entry is at least one byte (8 bytes a frame).
pub const MAX_ENTRIES: u8 = 8;

/// The PDOs a node offers in one direction: `entries[k]` mapping entries of PDO k + 1
/// (0-based k < [`MAX_PDOS`]); 0 = the node has no PDO k + 1, or it cannot be mapped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PdoSlots {
    /// Mapping entries per PDO (at most [`MAX_ENTRIES`] counted).
    pub entries: [u8; MAX_PDOS],
}

impl PdoSlots {
    /// The predefined connection set with 8 entries per mapping parameter: what the master
    /// plans with before it asks a node, and what fieldprobe's own nodes offer.
    pub const FULL: PdoSlots = PdoSlots {
        entries: [MAX_ENTRIES; MAX_PDOS],
    };

    /// PDOs the node has (with at least one entry).
    pub fn count(&self) -> usize {
        self.entries.iter().filter(|&&n| n > 0).count()
    }

    /// (PDO number k, entries) of the PDOs present, in order.
    pub fn present(&self) -> Vec<(u8, u8)> {
        (0..MAX_PDOS as u8)
            .zip(self.entries)
            .filter(|&(_, n)| n > 0)
            .collect()
    }

    /// `1 RPDO (0x1600: 8 entries)`, `4 TPDOs (0x1A00 … 0x1A03: 7, 6, 6, 8 entries)`.
    pub fn describe(&self, direction: Direction) -> String {
        let p = self.present();
        let what = match direction {
            Direction::Rx => "RPDO",
            Direction::Tx => "TPDO",
        };
        let Some(&(first, _)) = p.first() else {
            return format!("no {what}");
        };
        let last = p.last().map_or(first, |l| l.0);
        let counts: Vec<String> = p.iter().map(|(_, n)| n.to_string()).collect();
        let range = if first == last {
            format!("{:#06X}", direction.mapping_index(first))
        } else {
            format!(
                "{:#06X} … {:#06X}",
                direction.mapping_index(first),
                direction.mapping_index(last)
            )
        };
        format!(
            "{} {what}{} ({range}: {} entr{})",
            p.len(),
            if p.len() == 1 { "" } else { "s" },
            counts.join(", "),
            if counts.len() == 1 && counts[0] == "1" {
                "y"
            } else {
                "ies"
            }
        )
    }
}

/// A layout that fits no way into the PDOs a node offers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unfit {
    /// Direction.
    pub direction: Direction,
    /// What the node offers.
    pub slots: PdoSlots,
    /// PDOs the entries need packed as tightly as the node's largest mapping parameter allows.
    pub needed: usize,
    /// The entries that find no PDO in that packing: (index, sub-index, bytes).
    pub left: Vec<(u16, u8, usize)>,
}

impl std::fmt::Display for Unfit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let left: Vec<String> = self
            .left
            .iter()
            .map(|(i, s, n)| {
                format!(
                    "{i:#06X}:{s:02X} ({n} byte{})",
                    if *n == 1 { "" } else { "s" }
                )
            })
            .collect();
        write!(
            f,
            "the node offers {} and the {} process data need {} PDO{} (a PDO is one CAN frame of \
             at most 8 bytes, with as many objects as its mapping parameter has sub-indices); \
             no PDO is left for {}",
            self.slots.describe(self.direction),
            match self.direction {
                Direction::Rx => "output (RPDO)",
                Direction::Tx => "input (TPDO)",
            },
            self.needed,
            if self.needed == 1 { "" } else { "s" },
            left.join(", ")
        )
    }
}

/// [`super::plan_layout`] into the PDOs `slots` of a node (module documentation): the PDOs
/// with the node's PDO numbers and their default COB-IDs, or why it does not fit.
pub fn plan_layout_in(
    layout: &PdoLayout,
    direction: Direction,
    node: u8,
    slots: &PdoSlots,
) -> Result<Vec<Pdo>, Unfit> {
    let present = slots.present();
    let mut caps: Vec<u8> = present.iter().map(|&(_, n)| n.min(MAX_ENTRIES)).collect();
    caps.sort_unstable_by(|a, b| b.cmp(a));
    caps.dedup();
    let all: Vec<usize> = (0..layout.entries().len()).collect();
    for &cap in &caps {
        for split in [true, false] {
            let classes = if split {
                classes(layout, direction)
            } else {
                vec![(Trigger::Cyclic, all.clone())]
            };
            let bins: Vec<(Trigger, Vec<usize>)> = classes
                .into_iter()
                .flat_map(|(t, items)| {
                    first_fit_by(layout, items, usize::from(cap))
                        .into_iter()
                        .map(move |b| (t, b))
                })
                .collect();
            let fits = bins.len() <= present.len()
                && bins
                    .iter()
                    .zip(&present)
                    .all(|((_, b), &(_, n))| b.len() <= usize::from(n));
            if fits {
                let numbers: Vec<u8> = present.iter().map(|&(k, _)| k).collect();
                return Ok(build(layout, direction, node, bins, &numbers));
            }
        }
    }
    // The tightest packing: everything cyclic, the largest capacity.
    let cap = caps.first().copied().unwrap_or(0);
    let bins = if cap == 0 {
        vec![all]
    } else {
        first_fit_by(layout, all, usize::from(cap))
    };
    let left = bins
        .iter()
        .skip(present.len())
        .flatten()
        .filter_map(|&i| layout.entries().get(i))
        .map(|e| (e.index, e.sub, e.ty.size()))
        .collect();
    Err(Unfit {
        direction,
        slots: *slots,
        needed: bins.len(),
        left,
    })
}

/// The classes of the master's layout (module documentation of [`super`]): on-change TPDOs
/// first (probe 1 before probe 2), cyclic RPDOs first.
pub(super) fn classes(layout: &PdoLayout, direction: Direction) -> Vec<(Trigger, Vec<usize>)> {
    let mut classes: Vec<(Trigger, Vec<usize>)> = Vec::new();
    let mut cyclic = Vec::new();
    for (i, e) in layout.entries().iter().enumerate() {
        match on_change_class(direction, e.index) {
            None => cyclic.push(i),
            Some(probe) => {
                let t = Trigger::OnChange { probe };
                match classes.iter_mut().find(|(c, _)| *c == t) {
                    Some((_, v)) => v.push(i),
                    None => classes.push((t, vec![i])),
                }
            }
        }
    }
    classes.sort_by_key(|(t, _)| match t {
        Trigger::OnChange { probe: Some(p) } => *p,
        _ => u8::MAX,
    });
    match direction {
        Direction::Tx => classes.push((Trigger::Cyclic, cyclic)),
        Direction::Rx => classes.insert(0, (Trigger::Cyclic, cyclic)),
    }
    classes
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(specs: &[&str]) -> PdoLayout {
        PdoLayout::parse(specs).unwrap()
    }

    fn objects(p: &Pdo) -> Vec<u16> {
        p.mapped.iter().map(|m| m.index).collect()
    }

    fn slots(entries: [u8; MAX_PDOS]) -> PdoSlots {
        PdoSlots { entries }
    }

    #[test]
    fn one_rpdo_carries_every_set_point() {
        // Demaclenko emecdrv5: 0x1400 / 0x1600 only, 8 entries.
        let rx = layout(&["0x6040:00", "0x607A:00", "0x6060:00"]);
        let s = slots([8, 0, 0, 0]);
        let r = plan_layout_in(&rx, Direction::Rx, 3, &s).unwrap();
        assert_eq!(r.len(), 1);
        assert_eq!(objects(&r[0]), [0x6040, 0x607A, 0x6060]);
        assert_eq!(
            (r[0].number, r[0].cob, r[0].trigger),
            (0, 0x203, Trigger::Cyclic)
        );
        assert_eq!(s.describe(Direction::Rx), "1 RPDO (0x1600: 8 entries)");
    }

    #[test]
    fn few_entries_per_pdo_spread_over_more_pdos() {
        // Faulhaber MCBL 300x: 4 entries per mapping parameter; two entries only here.
        let tx = layout(&[
            "0x6041:00",
            "0x6064:00",
            "0x60F4:00",
            "0x6061:00",
            "0x6077:00",
        ]);
        let t = plan_layout_in(&tx, Direction::Tx, 1, &slots([2, 2, 2, 2])).unwrap();
        assert!(
            t.iter().all(|p| p.mapped.len() <= 2 && p.len() <= 8),
            "{t:?}"
        );
        assert_eq!(t.iter().map(|p| p.mapped.len()).sum::<usize>(), 5);
        // PDO numbers follow the node's: a gap at TPDO 2 is skipped.
        let t = plan_layout_in(&tx, Direction::Tx, 1, &slots([8, 0, 8, 8])).unwrap();
        let numbers: Vec<u8> = t.iter().map(|p| p.number).collect();
        assert_eq!(numbers, [0, 2]);
        assert_eq!(t[1].cob, 0x381);
    }

    #[test]
    fn what_fits_nowhere_names_the_objects_left() {
        let rx = layout(&["0x6040:00", "0x607A:00", "0x60B8:00", "0x6060:00"]);
        let e = plan_layout_in(&rx, Direction::Rx, 1, &slots([8, 0, 0, 0])).unwrap_err();
        assert_eq!(e.needed, 2);
        assert_eq!(e.left, vec![(0x6060, 0, 1)]);
        let text = e.to_string();
        assert!(text.contains("1 RPDO (0x1600: 8 entries)"), "{text}");
        assert!(
            text.contains("no PDO is left for 0x6060:00 (1 byte)"),
            "{text}"
        );
        let e = plan_layout_in(&rx, Direction::Rx, 1, &slots([0; 4])).unwrap_err();
        assert!(e.to_string().contains("no RPDO"), "{e}");
    }

    #[test]
    fn the_full_connection_set_plans_as_plan_layout() {
        let tx = layout(&[
            "0x6041:00",
            "0x6064:00",
            "0x60F4:00",
            "0x6061:00",
            "0x60B9:00",
            "0x60BA:00",
            "0x60BB:00",
            "0x60BC:00",
            "0x60BD:00",
            "0x6077:00",
        ]);
        assert_eq!(
            plan_layout_in(&tx, Direction::Tx, 2, &PdoSlots::FULL).unwrap(),
            super::super::plan_layout(&tx, Direction::Tx, 2).unwrap()
        );
    }
}
