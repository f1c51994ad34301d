//! PDOs (CiA 301 §7.2.2): packing a drive's process image into PDOs of at most 8 bytes, the
//! communication and mapping parameters, the remap procedure, and the copy between PDO data and
//! the drive's image.

use crate::drive::pdo::PdoLayout;

/// Receive (master → node) or transmit (node → master) PDO.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// RPDO: communication 0x1400 + k, mapping 0x1600 + k, COB-ID 0x200 + 0x100 k + node.
    Rx,
    /// TPDO: communication 0x1800 + k, mapping 0x1A00 + k, COB-ID 0x180 + 0x100 k + node.
    Tx,
}

impl Direction {
    /// Communication parameter index of PDO `k` (0-based).
    pub const fn comm_index(self, k: u8) -> u16 {
        match self {
            Direction::Rx => 0x1400 + k as u16,
            Direction::Tx => 0x1800 + k as u16,
        }
    }

    /// Mapping parameter index of PDO `k`.
    pub const fn mapping_index(self, k: u8) -> u16 {
        match self {
            Direction::Rx => 0x1600 + k as u16,
            Direction::Tx => 0x1A00 + k as u16,
        }
    }

    /// Default COB-ID of PDO `k` (0 … 3) of `node` (predefined connection set).
    pub const fn default_cob(self, k: u8, node: u8) -> u16 {
        let base = match self {
            Direction::Rx => 0x200,
            Direction::Tx => 0x180,
        };
        base + 0x100 * k as u16 + node as u16
    }
}

/// PDOs per direction of the predefined connection set.
pub const MAX_PDOS: usize = 4;

/// One mapped object: `len` bytes at `pdo_offset` in the PDO's data are bytes at
/// `image_offset` of the drive's image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mapped {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Bytes.
    pub len: usize,
    /// Offset in the PDO data.
    pub pdo_offset: usize,
    /// Offset in the drive image.
    pub image_offset: usize,
}

impl Mapped {
    /// CiA 301 mapping value `index << 16 | sub << 8 | bits`.
    pub fn mapping_value(&self) -> u32 {
        (u32::from(self.index) << 16) | (u32::from(self.sub) << 8) | (8 * self.len as u32)
    }
}

/// One PDO: its number, COB-ID and mapped objects.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pdo {
    /// Direction.
    pub direction: Direction,
    /// 0-based number (PDO 1 = 0).
    pub number: u8,
    /// COB-ID.
    pub cob: u16,
    /// Mapped objects in PDO order.
    pub mapped: Vec<Mapped>,
}

impl Pdo {
    /// Data length in bytes.
    pub fn len(&self) -> usize {
        self.mapped.iter().map(|m| m.len).sum()
    }

    /// `true` if nothing is mapped.
    pub fn is_empty(&self) -> bool {
        self.mapped.is_empty()
    }

    /// PDO data from the drive image.
    pub fn pack(&self, image: &[u8]) -> Vec<u8> {
        let mut d = vec![0u8; self.len()];
        for m in &self.mapped {
            if let (Some(dst), Some(src)) = (
                d.get_mut(m.pdo_offset..m.pdo_offset + m.len),
                image.get(m.image_offset..m.image_offset + m.len),
            ) {
                dst.copy_from_slice(src);
            }
        }
        d
    }

    /// Copy PDO data into the drive image; `false` (image untouched) if the length is wrong.
    pub fn unpack(&self, data: &[u8], image: &mut [u8]) -> bool {
        if data.len() != self.len() {
            return false;
        }
        for m in &self.mapped {
            if let (Some(dst), Some(src)) = (
                image.get_mut(m.image_offset..m.image_offset + m.len),
                data.get(m.pdo_offset..m.pdo_offset + m.len),
            ) {
                dst.copy_from_slice(src);
            }
        }
        true
    }

    /// The SDO writes of the CiA 301 remap procedure, in order: COB-ID invalid (bit 31),
    /// transmission type 1 (synchronous, every SYNC), mapping count 0, the entries, mapping
    /// count, COB-ID valid. Each write: (index, sub, little-endian data).
    pub fn remap_writes(&self) -> Vec<(u16, u8, Vec<u8>)> {
        let comm = self.direction.comm_index(self.number);
        let map = self.direction.mapping_index(self.number);
        let cob = u32::from(self.cob);
        let mut w = vec![
            (comm, 1, (cob | 0x8000_0000).to_le_bytes().to_vec()),
            (comm, 2, vec![1]),
            (map, 0, vec![0]),
        ];
        for (j, m) in self.mapped.iter().enumerate() {
            w.push((map, (j + 1) as u8, m.mapping_value().to_le_bytes().to_vec()));
        }
        w.push((map, 0, vec![self.mapped.len() as u8]));
        w.push((comm, 1, cob.to_le_bytes().to_vec()));
        w
    }
}

/// Pack the entries of `layout` into at most [`MAX_PDOS`] PDOs of ≤ 8 bytes for `node`: first
/// fit, largest entries first (entries are never split), PDOs then ordered by their first
/// entry's position in the layout. Errors say why it does not fit.
pub fn pack_layout(layout: &PdoLayout, direction: Direction, node: u8) -> Result<Vec<Pdo>, String> {
    let mut order: Vec<usize> = (0..layout.entries().len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(layout.entries()[i].ty.size()));
    let mut bins: Vec<Vec<usize>> = Vec::new();
    for i in order {
        let size = layout.entries()[i].ty.size();
        let used =
            |b: &Vec<usize>| -> usize { b.iter().map(|&j| layout.entries()[j].ty.size()).sum() };
        match bins.iter_mut().find(|b| used(b) + size <= 8) {
            Some(b) => b.push(i),
            None => bins.push(vec![i]),
        }
    }
    if bins.len() > MAX_PDOS {
        let total: usize = layout.entries().iter().map(|e| e.ty.size()).sum();
        return Err(format!(
            "{total} bytes of {} process data do not fit {MAX_PDOS} PDOs of 8 bytes",
            match direction {
                Direction::Rx => "output (RPDO)",
                Direction::Tx => "input (TPDO)",
            }
        ));
    }
    for b in &mut bins {
        b.sort_unstable();
    }
    bins.sort_by_key(|b| b.first().copied());
    Ok(bins
        .into_iter()
        .enumerate()
        .map(|(k, b)| {
            let mut off = 0;
            let mapped = b
                .into_iter()
                .map(|i| {
                    let e = &layout.entries()[i];
                    let m = Mapped {
                        index: e.index,
                        sub: e.sub,
                        len: e.ty.size(),
                        pdo_offset: off,
                        image_offset: e.offset,
                    };
                    off += m.len;
                    m
                })
                .collect();
            Pdo {
                direction,
                number: k as u8,
                cob: direction.default_cob(k as u8, node),
                mapped,
            }
        })
        .collect())
}
