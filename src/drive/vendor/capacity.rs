//! The PDOs a CANopen device offers by its EDS (issue 25): how many RPDOs / TPDOs and how many
//! entries each mapping parameter takes (CiA 301 §7.5.2.36 / .38: 0x1600 + k / 0x1A00 + k,
//! entries in sub-indices 1 … n), and the objects of a definition fitted into them the way
//! fieldprobe's CANopen master packs them (a PDO is one CAN frame: at most 8 bytes).
//!
//! The master asks the node itself at start-up and fits its layout then
//! (`link::canopen::fit`); `drive from-eds` uses the EDS to write a definition that fits:
//! * the mode of operation 0x6060 is not counted: where the set-points leave it no room the
//!   master writes it by SDO in PRE-OPERATIONAL;
//! * where the outputs still do not fit, the touch probe function 0x60B8 leaves, and with it
//!   the touch probe (the latch needs it);
//! * where the inputs do not fit, optional objects leave in this order: torque actual 0x6077,
//!   touch probe 2 negative / positive edge 0x60BD / 0x60BC, touch probe 1 negative edge
//!   0x60BB, following error actual 0x60F4;
//! * what still does not fit — the objects a CSP axis needs — refuses the definition.

/// Entries a PDO takes at most when every entry is at least one byte (8 bytes a frame).
const MAX_ENTRIES: u8 = 8;

/// The PDOs of a CANopen device by its EDS: mapping entries per RPDO / TPDO present, in PDO
/// order (at most 8 counted each).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PdoCapacity {
    /// Entries of each RPDO the device has.
    pub rx: Vec<u8>,
    /// Entries of each TPDO.
    pub tx: Vec<u8>,
}

impl PdoCapacity {
    /// `1 RPDO (8 entries)`, `4 TPDOs (7, 6, 6, 8 entries)`.
    pub fn describe(&self, rx: bool) -> String {
        let (list, what) = if rx {
            (&self.rx, "RPDO")
        } else {
            (&self.tx, "TPDO")
        };
        let n: Vec<String> = list.iter().map(u8::to_string).collect();
        format!(
            "{} {what}{} ({} entr{})",
            list.len(),
            if list.len() == 1 { "" } else { "s" },
            if n.is_empty() {
                "no".into()
            } else {
                n.join(", ")
            },
            if list.as_slice() == [1] { "y" } else { "ies" }
        )
    }
}

/// Do objects of these byte sizes fit PDOs with these entry counts? First fit, largest first,
/// at most 8 bytes and `cap` entries a PDO, tried for every capacity the PDOs have (largest
/// first); the bins go to the PDOs in order.
pub fn fits(sizes: &[usize], pdos: &[u8]) -> bool {
    let mut caps: Vec<u8> = pdos.iter().map(|&n| n.min(MAX_ENTRIES)).collect();
    caps.sort_unstable_by(|a, b| b.cmp(a));
    caps.dedup();
    let mut sorted = sizes.to_vec();
    sorted.sort_unstable_by(|a, b| b.cmp(a));
    if sorted.is_empty() {
        return true;
    }
    caps.iter().any(|&cap| {
        let mut bins: Vec<(usize, usize)> = Vec::new(); // (bytes, entries)
        for &s in &sorted {
            match bins
                .iter_mut()
                .find(|(b, n)| *n < usize::from(cap) && b + s <= 8)
            {
                Some(bin) => {
                    bin.0 += s;
                    bin.1 += 1;
                }
                None => bins.push((s, 1)),
            }
        }
        // Bins in PDO order need a PDO with at least as many entries.
        let mut counts: Vec<usize> = bins.iter().map(|b| b.1).collect();
        counts.sort_unstable_by(|a, b| b.cmp(a));
        let mut offered: Vec<usize> = pdos.iter().map(|&n| usize::from(n)).collect();
        offered.sort_unstable_by(|a, b| b.cmp(a));
        counts.len() <= offered.len() && counts.iter().zip(&offered).all(|(c, o)| c <= o)
    })
}

/// Inputs that leave when the TPDOs cannot carry them all (module documentation).
const TX_DROP: [u16; 5] = [0x6077, 0x60BD, 0x60BC, 0x60BB, 0x60F4];

/// What [`fit`] left out.
#[derive(Debug, Default)]
pub struct Fitted {
    /// Objects left out, with why.
    pub left_out: Vec<(u16, String)>,
    /// The touch probe function 0x60B8 had no room: the touch probe is off.
    pub probe_off: bool,
}

/// Fit the `rx` / `tx` objects (indices, `size` in bytes) into `cap` (module documentation);
/// `Err` names the required objects that find no room.
pub fn fit(
    cap: &PdoCapacity,
    rx: &mut Vec<u16>,
    tx: &mut Vec<u16>,
    size: impl Fn(u16) -> usize,
) -> Result<Fitted, Vec<String>> {
    let mut out = Fitted::default();
    let sizes = |list: &[u16], skip: Option<u16>| -> Vec<usize> {
        list.iter()
            .filter(|&&i| Some(i) != skip)
            .map(|&i| size(i))
            .collect()
    };
    let rx_room = format!(
        "no room in the {} the EDS gives (0x6060 not counted: the master writes it by SDO \
         where the RPDOs leave it none)",
        cap.describe(true)
    );
    if !fits(&sizes(rx, Some(0x6060)), &cap.rx) && rx.contains(&0x60B8) {
        rx.retain(|&i| i != 0x60B8);
        out.left_out.push((0x60B8, rx_room.clone()));
        out.probe_off = true;
        for i in 0x60B9..=0x60BD {
            if tx.contains(&i) {
                tx.retain(|&x| x != i);
                out.left_out.push((
                    i,
                    "the touch probe function 0x60B8 has no room in the RPDOs".into(),
                ));
            }
        }
    }
    let mut required = Vec::new();
    if !fits(&sizes(rx, Some(0x6060)), &cap.rx) {
        required.push(format!(
            "{}: {rx_room}",
            rx.iter()
                .filter(|&&i| i != 0x6060)
                .map(|i| format!("0x{i:04X}:00"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    let tx_room = format!("no room in the {} the EDS gives", cap.describe(false));
    for drop in TX_DROP {
        if fits(&sizes(tx, None), &cap.tx) {
            break;
        }
        if tx.contains(&drop) {
            tx.retain(|&i| i != drop);
            out.left_out.push((drop, tx_room.clone()));
        }
    }
    if !fits(&sizes(tx, None), &cap.tx) {
        required.push(format!(
            "{}: {tx_room}",
            tx.iter()
                .map(|i| format!("0x{i:04X}:00"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if required.is_empty() {
        Ok(out)
    } else {
        Err(required)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn size(i: u16) -> usize {
        match i {
            0x6060 | 0x6061 => 1,
            0x6040 | 0x6041 | 0x60B8 | 0x60B9 | 0x6077 => 2,
            _ => 4,
        }
    }

    #[test]
    fn packing_counts_bytes_and_entries() {
        assert!(fits(&[2, 4, 1], &[8]));
        assert!(!fits(&[2, 4, 2, 1], &[8]));
        assert!(!fits(&[2, 4, 1], &[2]));
        assert!(fits(&[2, 4, 1], &[2, 1]));
        assert!(fits(&[], &[]));
        assert!(!fits(&[1], &[]));
    }

    #[test]
    fn one_rpdo_with_a_touch_probe_keeps_it_and_0x6060_goes_by_sdo() {
        let cap = PdoCapacity {
            rx: vec![8],
            tx: vec![8; 4],
        };
        let mut rx = vec![0x6040, 0x607A, 0x6060, 0x60B8];
        let mut tx = vec![0x6041, 0x6064, 0x60F4, 0x6061, 0x60B9, 0x60BA, 0x6077];
        let f = fit(&cap, &mut rx, &mut tx, size).unwrap();
        assert!(f.left_out.is_empty() && !f.probe_off);
        assert_eq!(rx, [0x6040, 0x607A, 0x6060, 0x60B8]);
    }

    #[test]
    fn small_pdos_leave_optional_objects_out_then_refuse() {
        // 2 RPDOs of 1 entry: 0x6040 and 0x607A only, the touch probe goes (0x60B8 out, its
        // inputs with it); 3 TPDO entries: 0x6077 and 0x60F4 go.
        let cap = PdoCapacity {
            rx: vec![1, 1],
            tx: vec![2, 1],
        };
        let mut rx = vec![0x6040, 0x607A, 0x6060, 0x60B8];
        let mut tx = vec![0x6041, 0x6064, 0x60F4, 0x6061, 0x60B9, 0x60BA, 0x6077];
        let f = fit(&cap, &mut rx, &mut tx, size).unwrap();
        assert!(f.probe_off);
        assert_eq!(rx, [0x6040, 0x607A, 0x6060]);
        assert_eq!(tx, [0x6041, 0x6064, 0x6061]);
        let out: Vec<u16> = f.left_out.iter().map(|l| l.0).collect();
        assert_eq!(out, [0x60B8, 0x60B9, 0x60BA, 0x6077, 0x60F4]);
        assert!(
            f.left_out[0].1.contains("2 RPDOs (1, 1 entries)"),
            "{:?}",
            f.left_out
        );
        // One RPDO of one entry cannot carry controlword and target position.
        let cap = PdoCapacity {
            rx: vec![1],
            tx: vec![8],
        };
        let mut rx = vec![0x6040, 0x607A, 0x6060];
        let mut tx = vec![0x6041, 0x6064, 0x6061];
        let e = fit(&cap, &mut rx, &mut tx, size).unwrap_err();
        assert_eq!(e.len(), 1);
        assert!(
            e[0].starts_with("0x6040:00, 0x607A:00: no room in the 1 RPDO (1 entry)"),
            "{e:?}"
        );
    }
}
