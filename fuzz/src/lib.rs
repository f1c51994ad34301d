//! Helpers shared by the fuzz targets: a reader that turns fuzz bytes into a script of
//! operations, and the harnesses for the stateful targets (emulated EtherCAT segment,
//! ethercrab-driven mailbox clients against a hostile device).

#![forbid(unsafe_code)]

pub mod ecat;

/// Consumes fuzz bytes front to back; every read past the end yields zeros / empty slices,
/// so a script always ends.
#[derive(Debug)]
pub struct Bytes<'a> {
    data: &'a [u8],
}

impl<'a> Bytes<'a> {
    /// Reader over `data`.
    pub fn new(data: &'a [u8]) -> Self {
        Self { data }
    }

    /// Nothing left.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// Bytes left.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// Next byte (0 at the end).
    pub fn u8(&mut self) -> u8 {
        match self.data.split_first() {
            Some((b, rest)) => {
                self.data = rest;
                *b
            }
            None => 0,
        }
    }

    /// Next little-endian u16.
    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes([self.u8(), self.u8()])
    }

    /// Next little-endian u32.
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }

    /// Up to `n` next bytes.
    pub fn take(&mut self, n: usize) -> &'a [u8] {
        let n = n.min(self.data.len());
        let (a, b) = self.data.split_at(n);
        self.data = b;
        a
    }

    /// A length byte, then that many bytes.
    pub fn chunk(&mut self) -> &'a [u8] {
        let n = usize::from(self.u8());
        self.take(n)
    }

    /// A length (next byte, modulo `m`), then that many bytes.
    pub fn take_len8(&mut self, m: usize) -> &'a [u8] {
        let n = usize::from(self.u8()) % m.max(1);
        self.take(n)
    }

    /// A length (next u16, modulo `m`), then that many bytes.
    pub fn take_len16(&mut self, m: usize) -> &'a [u8] {
        let n = usize::from(self.u16()) % m.max(1);
        self.take(n)
    }

    /// Everything left.
    pub fn rest(&mut self) -> &'a [u8] {
        self.take(self.data.len())
    }
}
