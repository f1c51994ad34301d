//! EtherCAT frame and datagram wire format (ETG.1000.4).
//!
//! Layout, all multi-byte fields little-endian except the Ethernet header:
//!
//! ```text
//! Ethernet II  dst[6] src[6] (0x8100 TCI[2])? EtherType[2]=0x88A4          (big-endian)
//! EtherCAT     u16: length bits 0..10, reserved bit 11, type bits 12..15 (1 = DLPDU)
//! datagram     cmd u8, idx u8, address u32 (ADP u16 + ADO u16, or logical u32),
//!              u16: len bits 0..10, R 11..13, C bit 14 (circulating), M bit 15 (more follows),
//!              IRQ u16, data[len], WKC u16
//! ```
//!
//! Decoding is a checked view: [`Frame::parse`] validates the whole datagram chain once and
//! then hands out [`Datagram`]s that borrow their data from the input. An emulator rewrites a
//! frame in place with [`for_each_datagram_mut`]; a master builds one with [`FrameBuilder`].
//!
//! The mailbox layer (ETG.1000.4 §5.6 mailbox header, ETG.1000.6 CoE / SoE headers) sits on top:
//! [`MailboxHeader`], [`CoeHeader`], [`SdoCommand`] / [`SdoFrame`], [`SdoInfoHeader`],
//! [`SoeHeader`]. Mailbox type codes follow ETG.1000.4 (3 = CoE, 5 = SoE).
//!
//! Unknown codes are kept (`Unknown(u8)` variants) instead of failing; errors carry the byte
//! offset of the offending field. No function here panics on any input.

use thiserror::Error;

/// EtherType of EtherCAT frames.
pub const ETHERTYPE_ETHERCAT: u16 = 0x88A4;
/// EtherType of an IEEE 802.1Q VLAN tag.
pub const ETHERTYPE_VLAN: u16 = 0x8100;
/// Length of the Ethernet II header without a VLAN tag.
pub const ETHERNET_HEADER_LEN: usize = 14;
/// Length of the EtherCAT frame header.
pub const ETHERCAT_HEADER_LEN: usize = 2;
/// Datagram header length (cmd, idx, address, len/flags, IRQ).
pub const DATAGRAM_HEADER_LEN: usize = 10;
/// Length of the working counter that ends every datagram.
pub const WKC_LEN: usize = 2;
/// Largest value of the 11-bit length fields.
pub const MAX_LEN_11: usize = 0x7FF;
/// Minimum Ethernet frame length without FCS; shorter frames are padded by the builder.
pub const MIN_ETHERNET_FRAME: usize = 60;
/// Largest Ethernet frame without FCS and VLAN tag.
pub const MAX_ETHERNET_FRAME: usize = 1514;

/// Errors decoding or encoding EtherCAT wire data. Offsets count from the first byte of the
/// buffer handed to the decoder (Ethernet destination MAC for frames, mailbox header for
/// mailbox data).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum WireError {
    /// The buffer ended inside a field.
    #[error("truncated {what} at byte {offset}: need {need} bytes, {have} available")]
    Truncated {
        /// Which structure was being read.
        what: &'static str,
        /// Offset of the structure.
        offset: usize,
        /// Bytes the structure needs.
        need: usize,
        /// Bytes that were left.
        have: usize,
    },
    /// The EtherType (after an optional VLAN tag) is not 0x88A4.
    #[error("not an EtherCAT frame: EtherType {ethertype:#06x} at byte {offset}")]
    NotEtherCat {
        /// The EtherType found.
        ethertype: u16,
        /// Offset of the EtherType field.
        offset: usize,
    },
    /// The datagram chain does not fit the length in the EtherCAT header.
    #[error(
        "datagram at byte {offset} ends at byte {end}, beyond the EtherCAT payload end {limit}"
    )]
    DatagramOverrun {
        /// Offset of the datagram header.
        offset: usize,
        /// Where the datagram would end.
        end: usize,
        /// Where the EtherCAT payload ends.
        limit: usize,
    },
    /// A field holds a value that cannot be encoded or makes no sense.
    #[error("invalid {what} at byte {offset}: {value:#x}")]
    InvalidField {
        /// Field name.
        what: &'static str,
        /// Offset of the field (for encoding: offset in the output being built).
        offset: usize,
        /// The value.
        value: u32,
    },
    /// An encoded frame would exceed the Ethernet maximum.
    #[error("frame too long: {len} bytes (maximum {max})")]
    FrameTooLong {
        /// Length the frame would have.
        len: usize,
        /// Maximum.
        max: usize,
    },
}

fn truncated(what: &'static str, offset: usize, need: usize, buf_len: usize) -> WireError {
    WireError::Truncated {
        what,
        offset,
        need,
        have: buf_len.saturating_sub(offset),
    }
}

fn get<'a>(
    buf: &'a [u8],
    offset: usize,
    len: usize,
    what: &'static str,
) -> Result<&'a [u8], WireError> {
    offset
        .checked_add(len)
        .and_then(|end| buf.get(offset..end))
        .ok_or_else(|| truncated(what, offset, len, buf.len()))
}

fn le16(b: &[u8], at: usize) -> u16 {
    // Callers pass slices checked by `get`; a short slice yields 0 rather than a panic.
    match at.checked_add(2).and_then(|end| b.get(at..end)) {
        Some(s) => u16::from_le_bytes([s[0], s[1]]),
        None => 0,
    }
}

fn le32(b: &[u8], at: usize) -> u32 {
    match at.checked_add(4).and_then(|end| b.get(at..end)) {
        Some(s) => u32::from_le_bytes([s[0], s[1], s[2], s[3]]),
        None => 0,
    }
}

macro_rules! enum_with_unknown {
    (
        $(#[$m:meta])* pub enum $name:ident : $ty:ty {
            $( $(#[$vm:meta])* $var:ident = $val:expr ),+ $(,)?
        }
    ) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum $name {
            $( $(#[$vm])* $var, )+
            /// A code this decoder does not know; kept as is.
            Unknown($ty),
        }
        impl From<$ty> for $name {
            fn from(v: $ty) -> Self {
                match v { $( $val => $name::$var, )+ other => $name::Unknown(other) }
            }
        }
        impl From<$name> for $ty {
            fn from(v: $name) -> $ty {
                match v { $( $name::$var => $val, )+ $name::Unknown(other) => other }
            }
        }
    };
}

enum_with_unknown! {
    /// Datagram command (ETG.1000.4 table "EtherCAT command types").
    pub enum Command: u8 {
        /// No operation; slaves ignore the datagram.
        Nop = 0,
        /// Auto-increment physical read.
        Aprd = 1,
        /// Auto-increment physical write.
        Apwr = 2,
        /// Auto-increment physical read-write.
        Aprw = 3,
        /// Configured-address physical read.
        Fprd = 4,
        /// Configured-address physical write.
        Fpwr = 5,
        /// Configured-address physical read-write.
        Fprw = 6,
        /// Broadcast read (logical OR of all slaves' data).
        Brd = 7,
        /// Broadcast write.
        Bwr = 8,
        /// Broadcast read-write.
        Brw = 9,
        /// Logical read (through FMMUs).
        Lrd = 10,
        /// Logical write.
        Lwr = 11,
        /// Logical read-write.
        Lrw = 12,
        /// Auto-increment read, multiple write.
        Armw = 13,
        /// Configured-address read, multiple write.
        Frmw = 14,
    }
}

/// How a command addresses slaves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Addressing {
    /// No slave is addressed (NOP, unknown commands).
    None,
    /// ADP is a negative ring position, incremented by each slave (AP*, ARMW).
    Position,
    /// ADP is the configured station address (FP*, FRMW).
    Node,
    /// Every slave (B*).
    Broadcast,
    /// 32-bit logical address mapped through FMMUs (L*).
    Logical,
}

impl Command {
    /// Addressing mode of the command.
    pub fn addressing(self) -> Addressing {
        match self {
            Command::Aprd | Command::Apwr | Command::Aprw | Command::Armw => Addressing::Position,
            Command::Fprd | Command::Fpwr | Command::Fprw | Command::Frmw => Addressing::Node,
            Command::Brd | Command::Bwr | Command::Brw => Addressing::Broadcast,
            Command::Lrd | Command::Lwr | Command::Lrw => Addressing::Logical,
            Command::Nop | Command::Unknown(_) => Addressing::None,
        }
    }

    /// Mnemonic as in ETG.1000.4 ("FPRD"); `"?"` for unknown codes.
    pub fn name(self) -> &'static str {
        match self {
            Command::Nop => "NOP",
            Command::Aprd => "APRD",
            Command::Apwr => "APWR",
            Command::Aprw => "APRW",
            Command::Fprd => "FPRD",
            Command::Fpwr => "FPWR",
            Command::Fprw => "FPRW",
            Command::Brd => "BRD",
            Command::Bwr => "BWR",
            Command::Brw => "BRW",
            Command::Lrd => "LRD",
            Command::Lwr => "LWR",
            Command::Lrw => "LRW",
            Command::Armw => "ARMW",
            Command::Frmw => "FRMW",
            Command::Unknown(_) => "?",
        }
    }

    /// Numeric command code.
    pub fn code(self) -> u8 {
        self.into()
    }
}

impl std::fmt::Display for Command {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Command::Unknown(c) => write!(f, "CMD{c:#04x}"),
            other => f.write_str(other.name()),
        }
    }
}

enum_with_unknown! {
    /// EtherCAT frame header type (ETG.1000.4).
    pub enum FrameType: u8 {
        /// EtherCAT datagrams (DLPDU).
        Datagrams = 1,
        /// Network variables.
        NetworkVariables = 4,
        /// Mailbox gateway.
        Mailbox = 5,
    }
}

/// Ethernet addressing of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EthernetHeader {
    /// Destination MAC.
    pub dst: [u8; 6],
    /// Source MAC. A slave that processed the frame sets bit 1 of byte 0 (ETG.1000.4: the first device marks the frame).
    pub src: [u8; 6],
    /// VLAN tag control information when an 802.1Q tag precedes the EtherType.
    pub vlan_tci: Option<u16>,
}

/// A decoded EtherCAT datagram borrowing its data from the frame buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Datagram<'a> {
    /// Command.
    pub command: Command,
    /// Index chosen by the master to match replies.
    pub index: u8,
    /// Raw 32-bit address: ADP in the low 16 bits, ADO in the high 16 bits, or the logical
    /// address for L* commands.
    pub address: u32,
    /// Circulating frame flag (C, bit 14 of the length word).
    pub circulating: bool,
    /// More datagrams follow (M, bit 15).
    pub more_follows: bool,
    /// Event request (IRQ) field.
    pub irq: u16,
    /// Data, `len` bytes.
    pub data: &'a [u8],
    /// Working counter.
    pub wkc: u16,
}

impl<'a> Datagram<'a> {
    /// A datagram with C/M flags, IRQ and WKC zero.
    pub fn new(command: Command, index: u8, address: u32, data: &'a [u8]) -> Self {
        Datagram {
            command,
            index,
            address,
            circulating: false,
            more_follows: false,
            irq: 0,
            data,
            wkc: 0,
        }
    }

    /// Auto-increment / configured address (ADP) — low 16 bits of the address.
    pub fn adp(&self) -> u16 {
        self.address as u16
    }

    /// Physical memory offset (ADO) — high 16 bits of the address.
    pub fn ado(&self) -> u16 {
        (self.address >> 16) as u16
    }

    /// Logical address (L* commands): the whole 32-bit address.
    pub fn logical_address(&self) -> u32 {
        self.address
    }

    /// Encoded length of the datagram (header + data + WKC).
    pub fn wire_len(&self) -> usize {
        DATAGRAM_HEADER_LEN + self.data.len() + WKC_LEN
    }
}

/// Combine ADP and ADO into the raw datagram address.
pub fn physical_address(adp: u16, ado: u16) -> u32 {
    u32::from(adp) | (u32::from(ado) << 16)
}

/// Datagram header fields, decoded at a known offset.
#[derive(Debug, Clone, Copy)]
struct RawHeader {
    command: u8,
    index: u8,
    address: u32,
    len: usize,
    circulating: bool,
    more_follows: bool,
    irq: u16,
}

/// Decode the datagram header at `offset`; check that header, data and WKC end by `limit`.
/// Returns the header and the offset after the WKC.
fn datagram_at(buf: &[u8], offset: usize, limit: usize) -> Result<(RawHeader, usize), WireError> {
    let h = get(
        &buf[..limit.min(buf.len())],
        offset,
        DATAGRAM_HEADER_LEN,
        "datagram header",
    )?;
    let lenw = le16(h, 6);
    let len = usize::from(lenw & 0x07FF);
    let end = offset + DATAGRAM_HEADER_LEN + len + WKC_LEN;
    if end > limit {
        return Err(WireError::DatagramOverrun { offset, end, limit });
    }
    Ok((
        RawHeader {
            command: h[0],
            index: h[1],
            address: le32(h, 2),
            len,
            circulating: lenw & 0x4000 != 0,
            more_follows: lenw & 0x8000 != 0,
            irq: le16(h, 8),
        },
        end,
    ))
}

/// Offsets of a frame's EtherCAT payload.
#[derive(Debug, Clone, Copy)]
struct Layout {
    eth: EthernetHeader,
    ecat_len: usize,
    frame_type: FrameType,
    payload_start: usize,
    payload_end: usize,
}

fn layout(buf: &[u8]) -> Result<Layout, WireError> {
    let e = get(buf, 0, ETHERNET_HEADER_LEN, "Ethernet header")?;
    let mut dst = [0u8; 6];
    let mut src = [0u8; 6];
    dst.copy_from_slice(&e[0..6]);
    src.copy_from_slice(&e[6..12]);
    let mut off = 12;
    let mut ethertype = u16::from_be_bytes([e[12], e[13]]);
    let mut vlan_tci = None;
    if ethertype == ETHERTYPE_VLAN {
        let v = get(buf, 14, 4, "VLAN tag")?;
        vlan_tci = Some(u16::from_be_bytes([v[0], v[1]]));
        ethertype = u16::from_be_bytes([v[2], v[3]]);
        off = 16;
    }
    if ethertype != ETHERTYPE_ETHERCAT {
        return Err(WireError::NotEtherCat {
            ethertype,
            offset: off,
        });
    }
    let hdr_off = off + 2;
    let h = get(buf, hdr_off, ETHERCAT_HEADER_LEN, "EtherCAT header")?;
    let w = le16(h, 0);
    let ecat_len = usize::from(w & 0x07FF);
    let frame_type = FrameType::from((w >> 12) as u8);
    let payload_start = hdr_off + ETHERCAT_HEADER_LEN;
    let payload_end = payload_start + ecat_len;
    if payload_end > buf.len() {
        return Err(truncated(
            "EtherCAT payload",
            payload_start,
            ecat_len,
            buf.len(),
        ));
    }
    Ok(Layout {
        eth: EthernetHeader { dst, src, vlan_tci },
        ecat_len,
        frame_type,
        payload_start,
        payload_end,
    })
}

/// Walk the datagram chain (following the M flag) and return how many datagrams it holds.
fn count_datagrams(buf: &[u8], l: &Layout) -> Result<usize, WireError> {
    if l.frame_type != FrameType::Datagrams {
        return Ok(0);
    }
    let mut off = l.payload_start;
    let mut n = 0;
    loop {
        let (h, end) = datagram_at(buf, off, l.payload_end)?;
        n += 1;
        off = end;
        if !h.more_follows {
            return Ok(n);
        }
    }
}

/// A checked view of one EtherCAT frame (Ethernet II + EtherCAT header + datagrams).
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    buf: &'a [u8],
    layout: Layout,
    count: usize,
}

impl<'a> Frame<'a> {
    /// Decode and validate a frame starting at the Ethernet destination MAC. Bytes after the
    /// EtherCAT payload (Ethernet padding, FCS) are ignored, and so are payload bytes after the
    /// last datagram (M flag clear): TwinCAT pads an odd-length datagram chain by one byte in
    /// the EtherCAT length (9 frames of `twincat-akd-nc-mode.pcapng`). For frame types other than
    /// [`FrameType::Datagrams`] the header is checked and [`Frame::datagrams`] is empty.
    pub fn parse(buf: &'a [u8]) -> Result<Frame<'a>, WireError> {
        let layout = layout(buf)?;
        let count = count_datagrams(buf, &layout)?;
        Ok(Frame { buf, layout, count })
    }

    /// Ethernet addresses and VLAN tag.
    pub fn ethernet(&self) -> &EthernetHeader {
        &self.layout.eth
    }

    /// EtherCAT header length field (bytes of datagrams).
    pub fn ethercat_len(&self) -> usize {
        self.layout.ecat_len
    }

    /// EtherCAT header type field.
    pub fn frame_type(&self) -> FrameType {
        self.layout.frame_type
    }

    /// Offset of the EtherCAT header in the buffer (14, or 18 with a VLAN tag).
    pub fn ethercat_header_offset(&self) -> usize {
        self.layout.payload_start - ETHERCAT_HEADER_LEN
    }

    /// Bytes of the EtherCAT payload (datagrams), as declared by the header.
    pub fn payload(&self) -> &'a [u8] {
        self.buf
            .get(self.layout.payload_start..self.layout.payload_end)
            .unwrap_or(&[])
    }

    /// Number of datagrams.
    pub fn datagram_count(&self) -> usize {
        self.count
    }

    /// The datagrams in frame order.
    pub fn datagrams(&self) -> Datagrams<'a> {
        Datagrams {
            buf: self.buf,
            off: self.layout.payload_start,
            limit: self.layout.payload_end,
            left: self.count,
        }
    }

    /// The datagrams with their byte offsets (of the datagram header) in the buffer.
    pub fn datagrams_with_offsets(&self) -> impl Iterator<Item = (usize, Datagram<'a>)> + 'a {
        let mut it = self.datagrams();
        std::iter::from_fn(move || {
            let off = it.off;
            it.next().map(|d| (off, d))
        })
    }
}

/// Iterator over the datagrams of a validated [`Frame`].
#[derive(Debug, Clone)]
pub struct Datagrams<'a> {
    buf: &'a [u8],
    off: usize,
    limit: usize,
    left: usize,
}

impl<'a> Iterator for Datagrams<'a> {
    type Item = Datagram<'a>;

    fn next(&mut self) -> Option<Datagram<'a>> {
        if self.left == 0 {
            return None;
        }
        // Validated by `Frame::parse`; an error here cannot happen but ends iteration.
        let (h, end) = datagram_at(self.buf, self.off, self.limit).ok()?;
        let data_start = self.off + DATAGRAM_HEADER_LEN;
        let data = self.buf.get(data_start..data_start + h.len)?;
        let wkc = le16(self.buf, data_start + h.len);
        self.off = end;
        self.left -= 1;
        Some(Datagram {
            command: Command::from(h.command),
            index: h.index,
            address: h.address,
            circulating: h.circulating,
            more_follows: h.more_follows,
            irq: h.irq,
            data,
            wkc,
        })
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        (self.left, Some(self.left))
    }
}

/// Mutable view of one datagram inside a frame buffer, for emulators that process a frame in
/// place: data and WKC (and ADP for auto-increment addressing) can be rewritten.
#[derive(Debug)]
pub struct DatagramMut<'a> {
    /// Bytes from the datagram header to the end of the WKC.
    bytes: &'a mut [u8],
    /// Offset of the datagram header in the frame.
    offset: usize,
}

impl DatagramMut<'_> {
    fn data_len(&self) -> usize {
        self.bytes.len() - DATAGRAM_HEADER_LEN - WKC_LEN
    }

    /// Offset of the datagram header in the frame buffer.
    pub fn offset(&self) -> usize {
        self.offset
    }

    /// Command.
    pub fn command(&self) -> Command {
        Command::from(self.bytes[0])
    }

    /// Index.
    pub fn index(&self) -> u8 {
        self.bytes[1]
    }

    /// Raw 32-bit address (see [`Datagram::address`]).
    pub fn address(&self) -> u32 {
        le32(self.bytes, 2)
    }

    /// ADP (low 16 bits of the address).
    pub fn adp(&self) -> u16 {
        le16(self.bytes, 2)
    }

    /// ADO (high 16 bits of the address).
    pub fn ado(&self) -> u16 {
        le16(self.bytes, 4)
    }

    /// Rewrite ADP (slaves increment it for auto-increment addressing).
    pub fn set_adp(&mut self, adp: u16) {
        self.bytes[2..4].copy_from_slice(&adp.to_le_bytes());
    }

    /// Rewrite the whole address.
    pub fn set_address(&mut self, address: u32) {
        self.bytes[2..6].copy_from_slice(&address.to_le_bytes());
    }

    /// Circulating flag.
    pub fn circulating(&self) -> bool {
        self.bytes[7] & 0x40 != 0
    }

    /// Set or clear the circulating flag.
    pub fn set_circulating(&mut self, on: bool) {
        if on {
            self.bytes[7] |= 0x40;
        } else {
            self.bytes[7] &= !0x40;
        }
    }

    /// More-follows flag.
    pub fn more_follows(&self) -> bool {
        self.bytes[7] & 0x80 != 0
    }

    /// IRQ field.
    pub fn irq(&self) -> u16 {
        le16(self.bytes, 8)
    }

    /// Set the IRQ field.
    pub fn set_irq(&mut self, irq: u16) {
        self.bytes[8..10].copy_from_slice(&irq.to_le_bytes());
    }

    /// Data bytes.
    pub fn data(&self) -> &[u8] {
        let n = self.data_len();
        &self.bytes[DATAGRAM_HEADER_LEN..DATAGRAM_HEADER_LEN + n]
    }

    /// Data bytes, writable.
    pub fn data_mut(&mut self) -> &mut [u8] {
        let n = self.data_len();
        &mut self.bytes[DATAGRAM_HEADER_LEN..DATAGRAM_HEADER_LEN + n]
    }

    /// Working counter.
    pub fn wkc(&self) -> u16 {
        le16(self.bytes, self.bytes.len() - WKC_LEN)
    }

    /// Set the working counter.
    pub fn set_wkc(&mut self, wkc: u16) {
        let at = self.bytes.len() - WKC_LEN;
        self.bytes[at..].copy_from_slice(&wkc.to_le_bytes());
    }

    /// Add to the working counter (wrapping, as a 16-bit hardware counter does).
    pub fn add_wkc(&mut self, n: u16) {
        let w = self.wkc().wrapping_add(n);
        self.set_wkc(w);
    }

    /// Immutable snapshot of this datagram.
    pub fn as_datagram(&self) -> Datagram<'_> {
        let lenw = le16(self.bytes, 6);
        Datagram {
            command: self.command(),
            index: self.index(),
            address: self.address(),
            circulating: lenw & 0x4000 != 0,
            more_follows: lenw & 0x8000 != 0,
            irq: self.irq(),
            data: self.data(),
            wkc: self.wkc(),
        }
    }
}

/// Validate `frame` like [`Frame::parse`], then call `f` for each datagram in order with a
/// mutable view. Returns the number of datagrams visited. Nothing is modified when the frame
/// is invalid.
pub fn for_each_datagram_mut<F>(frame: &mut [u8], mut f: F) -> Result<usize, WireError>
where
    F: FnMut(DatagramMut<'_>),
{
    let l = layout(frame)?;
    let count = count_datagrams(frame, &l)?;
    let mut off = l.payload_start;
    for _ in 0..count {
        let (_, end) = datagram_at(frame, off, l.payload_end)?;
        let bytes = frame.get_mut(off..end).ok_or(WireError::DatagramOverrun {
            offset: off,
            end,
            limit: l.payload_end,
        })?;
        f(DatagramMut { bytes, offset: off });
        off = end;
    }
    Ok(count)
}

/// Mark a frame as processed by a slave: set bit 1 of the first source-MAC byte (as the first
/// device of a segment does). Returns `false` if the buffer is shorter than an Ethernet header.
pub fn mark_processed(frame: &mut [u8]) -> bool {
    if frame.len() < ETHERNET_HEADER_LEN {
        return false;
    }
    frame[6] |= 0x02;
    true
}

/// Builder for an EtherCAT frame with one or more datagrams. M flags are set automatically;
/// the result is padded to the Ethernet minimum of 60 bytes unless [`FrameBuilder::no_padding`]
/// is called.
#[derive(Debug, Clone)]
pub struct FrameBuilder {
    buf: Vec<u8>,
    /// Offset of the M-flag byte of the last datagram pushed.
    last_len_hi: Option<usize>,
    header_off: usize,
    pad: bool,
}

impl FrameBuilder {
    /// Start a frame with the given MACs and EtherType 0x88A4.
    pub fn new(dst: [u8; 6], src: [u8; 6]) -> Self {
        Self::with_vlan(dst, src, None)
    }

    /// Start a frame, optionally with an 802.1Q tag (`tci`) before the EtherType.
    pub fn with_vlan(dst: [u8; 6], src: [u8; 6], vlan_tci: Option<u16>) -> Self {
        let mut buf = Vec::with_capacity(MAX_ETHERNET_FRAME);
        buf.extend_from_slice(&dst);
        buf.extend_from_slice(&src);
        if let Some(tci) = vlan_tci {
            buf.extend_from_slice(&ETHERTYPE_VLAN.to_be_bytes());
            buf.extend_from_slice(&tci.to_be_bytes());
        }
        buf.extend_from_slice(&ETHERTYPE_ETHERCAT.to_be_bytes());
        let header_off = buf.len();
        buf.extend_from_slice(&[0, 0]);
        FrameBuilder {
            buf,
            last_len_hi: None,
            header_off,
            pad: true,
        }
    }

    /// Do not pad the frame to 60 bytes.
    pub fn no_padding(mut self) -> Self {
        self.pad = false;
        self
    }

    /// Bytes of datagrams so far.
    pub fn payload_len(&self) -> usize {
        self.buf.len() - self.header_off - ETHERCAT_HEADER_LEN
    }

    /// Append a datagram. Its `more_follows` is ignored (computed by the builder); `circulating`,
    /// `irq` and `wkc` are kept. Fails if the data exceeds 11 bits of length or the frame would
    /// exceed 1514 bytes (+4 with VLAN).
    pub fn push(&mut self, dg: &Datagram<'_>) -> Result<&mut Self, WireError> {
        let at = self.buf.len();
        if dg.data.len() > MAX_LEN_11 {
            return Err(WireError::InvalidField {
                what: "datagram length",
                offset: at + 6,
                value: dg.data.len() as u32,
            });
        }
        let max = MAX_ETHERNET_FRAME + (self.header_off - 12);
        let new_len = at + dg.wire_len();
        if new_len > max || new_len - self.header_off - ETHERCAT_HEADER_LEN > MAX_LEN_11 {
            return Err(WireError::FrameTooLong { len: new_len, max });
        }
        if let Some(prev) = self.last_len_hi {
            self.buf[prev] |= 0x80;
        }
        let lenw = (dg.data.len() as u16) | if dg.circulating { 0x4000 } else { 0 };
        self.buf.push(dg.command.code());
        self.buf.push(dg.index);
        self.buf.extend_from_slice(&dg.address.to_le_bytes());
        self.buf.extend_from_slice(&lenw.to_le_bytes());
        self.buf.extend_from_slice(&dg.irq.to_le_bytes());
        self.buf.extend_from_slice(dg.data);
        self.buf.extend_from_slice(&dg.wkc.to_le_bytes());
        self.last_len_hi = Some(at + 7);
        Ok(self)
    }

    /// Append a datagram from its parts (IRQ and WKC zero).
    pub fn push_command(
        &mut self,
        command: Command,
        index: u8,
        address: u32,
        data: &[u8],
    ) -> Result<&mut Self, WireError> {
        self.push(&Datagram::new(command, index, address, data))
    }

    /// Finish: write the EtherCAT header (type 1) and pad.
    pub fn build(&self) -> Vec<u8> {
        let mut out = self.buf.clone();
        let len = self.payload_len() as u16 & 0x07FF;
        let w = len | (u16::from(u8::from(FrameType::Datagrams)) << 12);
        out[self.header_off..self.header_off + 2].copy_from_slice(&w.to_le_bytes());
        if self.pad && out.len() < MIN_ETHERNET_FRAME {
            out.resize(MIN_ETHERNET_FRAME, 0);
        }
        out
    }
}

// ---------------------------------------------------------------------------------------------
// Mailbox (ETG.1000.4 §5.6, ETG.1000.6 §5.6)

enum_with_unknown! {
    /// Mailbox type, low nibble of mailbox header byte 5 (ETG.1000.4 mailbox header).
    pub enum MailboxType: u8 {
        /// Mailbox error reply.
        Error = 0,
        /// ADS over EtherCAT.
        Aoe = 1,
        /// Ethernet over EtherCAT.
        Eoe = 2,
        /// CANopen over EtherCAT.
        Coe = 3,
        /// File access over EtherCAT.
        Foe = 4,
        /// Servo drive profile over EtherCAT (SERCOS, ETG.1000.6 SoE).
        Soe = 5,
        /// Vendor specific.
        Voe = 15,
    }
}

/// Mailbox header (6 bytes) in front of every mailbox service PDU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MailboxHeader {
    /// Length of the service data after this header.
    pub length: u16,
    /// Station address of the source (slave → master) or destination.
    pub address: u16,
    /// Channel (bits 0..5 of byte 4).
    pub channel: u8,
    /// Priority (bits 6..7 of byte 4).
    pub priority: u8,
    /// Mailbox type (bits 0..3 of byte 5).
    pub mailbox_type: MailboxType,
    /// Counter 1..7 (bits 4..6 of byte 5); 0 on the first message.
    pub counter: u8,
}

impl MailboxHeader {
    /// Encoded length.
    pub const LEN: usize = 6;

    /// Decode the header at the start of `buf` and return the service data it declares
    /// (`length` bytes; the rest of a mailbox-sized buffer is padding).
    pub fn parse(buf: &[u8]) -> Result<(MailboxHeader, &[u8]), WireError> {
        let h = get(buf, 0, Self::LEN, "mailbox header")?;
        let length = le16(h, 0);
        let hdr = MailboxHeader {
            length,
            address: le16(h, 2),
            channel: h[4] & 0x3F,
            priority: h[4] >> 6,
            mailbox_type: MailboxType::from(h[5] & 0x0F),
            counter: (h[5] >> 4) & 0x07,
        };
        let body = get(buf, Self::LEN, usize::from(length), "mailbox service data")?;
        Ok((hdr, body))
    }

    /// Encode (channel and priority are masked to their bit widths, counter to 3 bits).
    pub fn encode(&self) -> [u8; 6] {
        let l = self.length.to_le_bytes();
        let a = self.address.to_le_bytes();
        [
            l[0],
            l[1],
            a[0],
            a[1],
            (self.channel & 0x3F) | ((self.priority & 0x03) << 6),
            (u8::from(self.mailbox_type) & 0x0F) | ((self.counter & 0x07) << 4),
        ]
    }
}

enum_with_unknown! {
    /// CoE service, bits 12..15 of the CoE header (ETG.1000.6 table "CoE service").
    pub enum CoeService: u8 {
        /// Emergency message.
        Emergency = 1,
        /// SDO request.
        SdoRequest = 2,
        /// SDO response.
        SdoResponse = 3,
        /// TxPDO.
        TxPdo = 4,
        /// RxPDO.
        RxPdo = 5,
        /// TxPDO remote request.
        TxPdoRemoteRequest = 6,
        /// RxPDO remote request.
        RxPdoRemoteRequest = 7,
        /// SDO information.
        SdoInformation = 8,
    }
}

/// CoE header (2 bytes): PDO number bits 0..8, service bits 12..15.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CoeHeader {
    /// Number (PDO number; 0 for SDO services).
    pub number: u16,
    /// Service.
    pub service: CoeService,
}

impl CoeHeader {
    /// Encoded length.
    pub const LEN: usize = 2;

    /// Decode the header at the start of the mailbox service data; returns it and the rest.
    pub fn parse(buf: &[u8]) -> Result<(CoeHeader, &[u8]), WireError> {
        let h = get(buf, 0, Self::LEN, "CoE header")?;
        let w = le16(h, 0);
        Ok((
            CoeHeader {
                number: w & 0x01FF,
                service: CoeService::from((w >> 12) as u8),
            },
            &buf[Self::LEN..],
        ))
    }

    /// Encode.
    pub fn encode(&self) -> [u8; 2] {
        ((self.number & 0x01FF) | (u16::from(u8::from(self.service) & 0x0F) << 12)).to_le_bytes()
    }
}

/// Whether an SDO command byte travels master → slave (request, client command specifier
/// `ccs`) or slave → master (response, server command specifier `scs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoDirection {
    /// CoE service 2.
    Request,
    /// CoE service 3.
    Response,
}

/// Decoded SDO command byte (CiA 301 §7.2.4.3, ETG.1000.6 §5.6.2 with complete access).
/// `unused` counts bytes of the data field that carry no data (`n`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoCommand {
    /// ccs 1.
    InitiateDownloadRequest {
        /// Complete access (bit 4).
        complete_access: bool,
        /// Expedited (bit 1).
        expedited: bool,
        /// Size indicated (bit 0).
        size_indicated: bool,
        /// Bytes without data (bits 2..3; only with expedited and size indicated).
        unused: u8,
    },
    /// scs 3.
    InitiateDownloadResponse,
    /// ccs 0.
    DownloadSegmentRequest {
        /// Toggle bit (bit 4).
        toggle: bool,
        /// Bytes without data (bits 1..3).
        unused: u8,
        /// Last segment (bit 0).
        last: bool,
    },
    /// scs 1.
    DownloadSegmentResponse {
        /// Toggle bit (bit 4).
        toggle: bool,
    },
    /// ccs 2.
    InitiateUploadRequest {
        /// Complete access (bit 4).
        complete_access: bool,
    },
    /// scs 2.
    InitiateUploadResponse {
        /// Complete access (bit 4).
        complete_access: bool,
        /// Expedited (bit 1).
        expedited: bool,
        /// Size indicated (bit 0).
        size_indicated: bool,
        /// Bytes without data (bits 2..3).
        unused: u8,
    },
    /// ccs 3.
    UploadSegmentRequest {
        /// Toggle bit (bit 4).
        toggle: bool,
    },
    /// scs 0.
    UploadSegmentResponse {
        /// Toggle bit (bit 4).
        toggle: bool,
        /// Bytes without data (bits 1..3).
        unused: u8,
        /// Last segment (bit 0).
        last: bool,
    },
    /// Command specifier 4 in either direction.
    Abort,
    /// Block transfers and reserved specifiers; the raw byte.
    Other(u8),
}

impl SdoCommand {
    /// Decode a command byte.
    pub fn decode(byte: u8, dir: SdoDirection) -> SdoCommand {
        let cs = byte >> 5;
        let toggle = byte & 0x10 != 0;
        let init = || {
            (
                toggle,
                byte & 0x02 != 0,
                byte & 0x01 != 0,
                (byte >> 2) & 0x03,
            )
        };
        match (dir, cs) {
            (_, 4) => SdoCommand::Abort,
            (SdoDirection::Request, 1) => {
                let (complete_access, expedited, size_indicated, unused) = init();
                SdoCommand::InitiateDownloadRequest {
                    complete_access,
                    expedited,
                    size_indicated,
                    unused,
                }
            }
            (SdoDirection::Request, 0) => SdoCommand::DownloadSegmentRequest {
                toggle,
                unused: (byte >> 1) & 0x07,
                last: byte & 0x01 != 0,
            },
            (SdoDirection::Request, 2) => SdoCommand::InitiateUploadRequest {
                complete_access: toggle,
            },
            (SdoDirection::Request, 3) => SdoCommand::UploadSegmentRequest { toggle },
            (SdoDirection::Response, 3) => SdoCommand::InitiateDownloadResponse,
            (SdoDirection::Response, 1) => SdoCommand::DownloadSegmentResponse { toggle },
            (SdoDirection::Response, 2) => {
                let (complete_access, expedited, size_indicated, unused) = init();
                SdoCommand::InitiateUploadResponse {
                    complete_access,
                    expedited,
                    size_indicated,
                    unused,
                }
            }
            (SdoDirection::Response, 0) => SdoCommand::UploadSegmentResponse {
                toggle,
                unused: (byte >> 1) & 0x07,
                last: byte & 0x01 != 0,
            },
            _ => SdoCommand::Other(byte),
        }
    }

    /// Encode to the command byte.
    pub fn encode(self) -> u8 {
        let b = |x: bool, bit: u8| if x { 1u8 << bit } else { 0 };
        match self {
            SdoCommand::InitiateDownloadRequest {
                complete_access,
                expedited,
                size_indicated,
                unused,
            } => {
                0x20 | b(complete_access, 4)
                    | ((unused & 3) << 2)
                    | b(expedited, 1)
                    | b(size_indicated, 0)
            }
            SdoCommand::InitiateDownloadResponse => 0x60,
            SdoCommand::DownloadSegmentRequest {
                toggle,
                unused,
                last,
            } => b(toggle, 4) | ((unused & 7) << 1) | b(last, 0),
            SdoCommand::DownloadSegmentResponse { toggle } => 0x20 | b(toggle, 4),
            SdoCommand::InitiateUploadRequest { complete_access } => 0x40 | b(complete_access, 4),
            SdoCommand::InitiateUploadResponse {
                complete_access,
                expedited,
                size_indicated,
                unused,
            } => {
                0x40 | b(complete_access, 4)
                    | ((unused & 3) << 2)
                    | b(expedited, 1)
                    | b(size_indicated, 0)
            }
            SdoCommand::UploadSegmentRequest { toggle } => 0x60 | b(toggle, 4),
            SdoCommand::UploadSegmentResponse {
                toggle,
                unused,
                last,
            } => b(toggle, 4) | ((unused & 7) << 1) | b(last, 0),
            SdoCommand::Abort => 0x80,
            SdoCommand::Other(x) => x,
        }
    }

    /// Whether the command carries index and subindex (initiate and abort) rather than a
    /// segment.
    pub fn has_index(self) -> bool {
        matches!(
            self,
            SdoCommand::InitiateDownloadRequest { .. }
                | SdoCommand::InitiateDownloadResponse
                | SdoCommand::InitiateUploadRequest { .. }
                | SdoCommand::InitiateUploadResponse { .. }
                | SdoCommand::Abort
        )
    }
}

/// An SDO request or response after the CoE header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SdoFrame<'a> {
    /// Decoded command byte.
    pub command: SdoCommand,
    /// Object index (initiate / abort only).
    pub index: Option<u16>,
    /// Subindex (initiate / abort only).
    pub subindex: Option<u8>,
    /// Abort code (abort only, u32 at offset 4).
    pub abort_code: Option<u32>,
    /// Bytes after the command byte (segments) or after index/subindex (initiate): the
    /// expedited data or size, or the normal-transfer payload.
    pub data: &'a [u8],
}

impl<'a> SdoFrame<'a> {
    /// Decode the SDO part of a CoE service 2/3 body (the bytes after the CoE header).
    pub fn parse(buf: &'a [u8], dir: SdoDirection) -> Result<SdoFrame<'a>, WireError> {
        let c = get(buf, 0, 1, "SDO command")?;
        let command = SdoCommand::decode(c[0], dir);
        if !command.has_index() {
            return Ok(SdoFrame {
                command,
                index: None,
                subindex: None,
                abort_code: None,
                data: &buf[1..],
            });
        }
        let h = get(buf, 0, 4, "SDO index")?;
        let index = le16(h, 1);
        let subindex = h[3];
        let abort_code = if command == SdoCommand::Abort {
            Some(le32(get(buf, 4, 4, "SDO abort code")?, 0))
        } else {
            None
        };
        Ok(SdoFrame {
            command,
            index: Some(index),
            subindex: Some(subindex),
            abort_code,
            data: &buf[4..],
        })
    }
}

enum_with_unknown! {
    /// SDO information opcode (ETG.1000.6 table "SDO Information header").
    pub enum SdoInfoOpcode: u8 {
        /// Get OD list request.
        GetOdListRequest = 1,
        /// Get OD list response.
        GetOdListResponse = 2,
        /// Get object description request.
        GetObjectDescriptionRequest = 3,
        /// Get object description response.
        GetObjectDescriptionResponse = 4,
        /// Get entry description request.
        GetEntryDescriptionRequest = 5,
        /// Get entry description response.
        GetEntryDescriptionResponse = 6,
        /// SDO information error request.
        ErrorRequest = 7,
    }
}

/// SDO information header (4 bytes after the CoE header, service 8).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SdoInfoHeader {
    /// Opcode (bits 0..6 of byte 0).
    pub opcode: SdoInfoOpcode,
    /// More fragments follow (bit 7 of byte 0).
    pub incomplete: bool,
    /// Fragments left (u16 at offset 2).
    pub fragments_left: u16,
}

impl SdoInfoHeader {
    /// Encoded length.
    pub const LEN: usize = 4;

    /// Decode; returns the header and the rest.
    pub fn parse(buf: &[u8]) -> Result<(SdoInfoHeader, &[u8]), WireError> {
        let h = get(buf, 0, Self::LEN, "SDO information header")?;
        Ok((
            SdoInfoHeader {
                opcode: SdoInfoOpcode::from(h[0] & 0x7F),
                incomplete: h[0] & 0x80 != 0,
                fragments_left: le16(h, 2),
            },
            &buf[Self::LEN..],
        ))
    }

    /// Encode.
    pub fn encode(&self) -> [u8; 4] {
        let f = self.fragments_left.to_le_bytes();
        [
            (u8::from(self.opcode) & 0x7F) | if self.incomplete { 0x80 } else { 0 },
            0,
            f[0],
            f[1],
        ]
    }
}

enum_with_unknown! {
    /// SoE opcode (bits 0..2 of SoE header byte 0; ETG.1000.6).
    pub enum SoeOpcode: u8 {
        /// Read request.
        ReadRequest = 1,
        /// Read response.
        ReadResponse = 2,
        /// Write request.
        WriteRequest = 3,
        /// Write response.
        WriteResponse = 4,
        /// Notification.
        Notification = 5,
        /// Emergency (SOEM) / slave info (ETG.1000.6).
        Emergency = 6,
    }
}

/// SoE header (4 bytes after the mailbox header, mailbox type 5; ETG.1000.6).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SoeHeader {
    /// Opcode (bits 0..2).
    pub opcode: SoeOpcode,
    /// More fragments follow (bit 3); then `idn` holds the fragments left.
    pub incomplete: bool,
    /// Error (bit 4); the data is a 2-byte SERCOS error code.
    pub error: bool,
    /// Drive number (bits 5..7).
    pub drive_no: u8,
    /// Element flags (0x01 data state, 0x02 name, 0x04 attribute, 0x08 unit, 0x10 min, 0x20 max,
    /// 0x40 value, 0x80 default).
    pub elements: u8,
    /// IDN (bit 15 P/S, bits 12..14 parameter set, bits 0..11 number), or fragments left when
    /// `incomplete`.
    pub idn: u16,
}

impl SoeHeader {
    /// Encoded length.
    pub const LEN: usize = 4;

    /// Decode; returns the header and the rest.
    pub fn parse(buf: &[u8]) -> Result<(SoeHeader, &[u8]), WireError> {
        let h = get(buf, 0, Self::LEN, "SoE header")?;
        Ok((
            SoeHeader {
                opcode: SoeOpcode::from(h[0] & 0x07),
                incomplete: h[0] & 0x08 != 0,
                error: h[0] & 0x10 != 0,
                drive_no: h[0] >> 5,
                elements: h[1],
                idn: le16(h, 2),
            },
            &buf[Self::LEN..],
        ))
    }

    /// Encode (fields masked to their bit widths).
    pub fn encode(&self) -> [u8; 4] {
        let i = self.idn.to_le_bytes();
        let b0 = (u8::from(self.opcode) & 0x07)
            | if self.incomplete { 0x08 } else { 0 }
            | if self.error { 0x10 } else { 0 }
            | ((self.drive_no & 0x07) << 5);
        [b0, self.elements, i[0], i[1]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_codes_round_trip() {
        for c in 0..=255u8 {
            assert_eq!(Command::from(c).code(), c);
        }
        assert_eq!(Command::from(14), Command::Frmw);
        assert_eq!(Command::from(15), Command::Unknown(15));
    }

    #[test]
    fn sdo_command_bytes() {
        // ethercrab's upload init 0x40, complete access 0x50, expedited download 0x2F
        assert_eq!(
            SdoCommand::decode(0x40, SdoDirection::Request),
            SdoCommand::InitiateUploadRequest {
                complete_access: false
            }
        );
        assert_eq!(
            SdoCommand::decode(0x50, SdoDirection::Request).encode(),
            0x50
        );
        let d = SdoCommand::decode(0x2F, SdoDirection::Request);
        assert_eq!(
            d,
            SdoCommand::InitiateDownloadRequest {
                complete_access: false,
                expedited: true,
                size_indicated: true,
                unused: 3
            }
        );
        assert_eq!(d.encode(), 0x2F);
        assert_eq!(
            SdoCommand::decode(0x43, SdoDirection::Response).encode(),
            0x43
        );
        assert_eq!(
            SdoCommand::decode(0x80, SdoDirection::Response),
            SdoCommand::Abort
        );
        for b in 0..=255u8 {
            for dir in [SdoDirection::Request, SdoDirection::Response] {
                let c = SdoCommand::decode(b, dir);
                if !matches!(c, SdoCommand::Abort | SdoCommand::Other(_)) {
                    // reserved bits aside, encoding reproduces the byte
                    assert_eq!(SdoCommand::decode(c.encode(), dir), c, "{b:#x}");
                }
            }
        }
    }
}
