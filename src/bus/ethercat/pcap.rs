//! pcap / pcapng capture files of EtherCAT traffic.
//!
//! [`CaptureReader`] decodes an in-memory capture — classic pcap (either byte order, µs or ns
//! magic) or pcapng (section header, interface description, enhanced and simple packet blocks;
//! other block types are skipped; byte order per section from the SHB magic) — into
//! [`Record`]s that borrow the packet bytes. [`PcapWriter`] writes classic pcap with
//! `LINKTYPE_ETHERNET` that Wireshark reads, at µs or ns resolution.
//!
//! Formats: classic pcap per the tcpdump `pcap-savefile(5)` description; pcapng per the IETF
//! draft "PCAP Next Generation Dump File Format" (block type, total length, body, total length;
//! `if_tsresol` option 9 and `if_tsoffset` option 14 of the IDB).
//!
//! No function here panics on any input; errors name the byte offset and the block.

use std::io::Write;
use std::path::Path;

use thiserror::Error;

/// Link type of Ethernet frames (`LINKTYPE_ETHERNET`).
pub const LINKTYPE_ETHERNET: u16 = 1;

const PCAP_MAGIC_US: u32 = 0xA1B2_C3D4;
const PCAP_MAGIC_NS: u32 = 0xA1B2_3C4D;
const PCAPNG_SHB: u32 = 0x0A0D_0D0A;
const PCAPNG_BYTE_ORDER_MAGIC: u32 = 0x1A2B_3C4D;
const PCAPNG_IDB: u32 = 1;
const PCAPNG_SPB: u32 = 3;
const PCAPNG_EPB: u32 = 6;
/// Obsolete pcapng packet block, still written by some tools.
const PCAPNG_PB: u32 = 2;

/// Errors reading or writing captures.
#[derive(Debug, Error)]
pub enum PcapError {
    /// The file starts with neither a pcap nor a pcapng magic number.
    #[error("not a pcap or pcapng file: magic {magic:#010x} at byte 0")]
    BadMagic {
        /// The first four bytes, read big-endian.
        magic: u32,
    },
    /// The data ended inside a header, record or block.
    #[error("truncated {what} at byte {offset}: need {need} bytes, {have} available")]
    Truncated {
        /// What was being read.
        what: &'static str,
        /// Offset of the structure.
        offset: usize,
        /// Bytes needed.
        need: usize,
        /// Bytes available.
        have: usize,
    },
    /// A block or record is malformed.
    #[error("invalid {what} in {block} at byte {offset}: {value:#x}")]
    Invalid {
        /// Field.
        what: &'static str,
        /// Block or record kind.
        block: &'static str,
        /// Offset of the block or record.
        offset: usize,
        /// Offending value.
        value: u64,
    },
    /// A packet block names an interface that no IDB in its section described.
    #[error(
        "{block} at byte {offset} refers to interface {interface}, but the section has {known}"
    )]
    UnknownInterface {
        /// Block kind.
        block: &'static str,
        /// Offset of the block.
        offset: usize,
        /// Interface id.
        interface: u32,
        /// Number of interfaces described.
        known: usize,
    },
    /// Reading or writing a file failed.
    #[error("capture I/O: {0}")]
    Io(#[from] std::io::Error),
}

/// One captured packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Record<'a> {
    /// Capture time in ns since the Unix epoch; `None` for pcapng simple packet blocks, which
    /// carry no timestamp.
    pub timestamp_ns: Option<u64>,
    /// Link type of the interface (1 = Ethernet).
    pub linktype: u16,
    /// pcapng interface id (0 for classic pcap).
    pub interface: u32,
    /// Length of the packet on the wire (may exceed `data.len()` when the capture was cut).
    pub original_len: u32,
    /// Captured bytes.
    pub data: &'a [u8],
}

/// Container format of a capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaptureFormat {
    /// Classic pcap.
    Pcap,
    /// pcapng.
    PcapNg,
}

#[derive(Debug, Clone, Copy)]
struct Interface {
    linktype: u16,
    snaplen: u32,
    /// Timestamp units: (is_binary, exponent) — 10^-e or 2^-e seconds.
    tsresol: (bool, u8),
    tsoffset_s: i64,
}

fn ticks_to_ns(ticks: u64, (binary, e): (bool, u8)) -> u64 {
    let t = u128::from(ticks);
    let ns = if binary {
        if e >= 128 {
            0
        } else {
            t.saturating_mul(1_000_000_000) >> e
        }
    } else if e <= 9 {
        t.saturating_mul(10u128.pow(u32::from(9 - e)))
    } else if e <= 38 {
        t / 10u128.pow(u32::from(e - 9))
    } else {
        0
    };
    u64::try_from(ns).unwrap_or(u64::MAX)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Endian {
    Little,
    Big,
}

impl Endian {
    fn u16(self, b: [u8; 2]) -> u16 {
        match self {
            Endian::Little => u16::from_le_bytes(b),
            Endian::Big => u16::from_be_bytes(b),
        }
    }
    fn u32(self, b: [u8; 4]) -> u32 {
        match self {
            Endian::Little => u32::from_le_bytes(b),
            Endian::Big => u32::from_be_bytes(b),
        }
    }
}

fn slice<'a>(
    buf: &'a [u8],
    offset: usize,
    len: usize,
    what: &'static str,
) -> Result<&'a [u8], PcapError> {
    offset
        .checked_add(len)
        .and_then(|end| buf.get(offset..end))
        .ok_or(PcapError::Truncated {
            what,
            offset,
            need: len,
            have: buf.len().saturating_sub(offset),
        })
}

fn rd16(e: Endian, buf: &[u8], at: usize, what: &'static str) -> Result<u16, PcapError> {
    let s = slice(buf, at, 2, what)?;
    Ok(e.u16([s[0], s[1]]))
}

fn rd32(e: Endian, buf: &[u8], at: usize, what: &'static str) -> Result<u32, PcapError> {
    let s = slice(buf, at, 4, what)?;
    Ok(e.u32([s[0], s[1], s[2], s[3]]))
}

#[derive(Debug, Clone)]
enum State {
    Pcap {
        endian: Endian,
        nanos: bool,
        linktype: u16,
    },
    PcapNg {
        endian: Endian,
        interfaces: Vec<Interface>,
    },
}

/// Iterator over the records of an in-memory capture. After the first error it yields nothing.
#[derive(Debug, Clone)]
pub struct CaptureReader<'a> {
    buf: &'a [u8],
    pos: usize,
    state: State,
    failed: bool,
}

impl<'a> CaptureReader<'a> {
    /// Recognise the format from the magic number and read the file header (classic pcap) or
    /// prepare to read blocks (pcapng).
    pub fn new(buf: &'a [u8]) -> Result<CaptureReader<'a>, PcapError> {
        let m = slice(buf, 0, 4, "file magic")?;
        let be = u32::from_be_bytes([m[0], m[1], m[2], m[3]]);
        let le = u32::from_le_bytes([m[0], m[1], m[2], m[3]]);
        let classic = |endian, nanos| -> Result<CaptureReader<'a>, PcapError> {
            slice(buf, 0, 24, "pcap file header")?;
            let major = rd16(endian, buf, 4, "pcap version")?;
            if major != 2 {
                return Err(PcapError::Invalid {
                    what: "major version",
                    block: "pcap file header",
                    offset: 4,
                    value: u64::from(major),
                });
            }
            let network = rd32(endian, buf, 20, "pcap link type")?;
            Ok(CaptureReader {
                buf,
                pos: 24,
                state: State::Pcap {
                    endian,
                    nanos,
                    linktype: (network & 0xFFFF) as u16,
                },
                failed: false,
            })
        };
        match (be, le) {
            (_, PCAP_MAGIC_US) => classic(Endian::Little, false),
            (_, PCAP_MAGIC_NS) => classic(Endian::Little, true),
            (PCAP_MAGIC_US, _) => classic(Endian::Big, false),
            (PCAP_MAGIC_NS, _) => classic(Endian::Big, true),
            (PCAPNG_SHB, _) => Ok(CaptureReader {
                buf,
                pos: 0,
                state: State::PcapNg {
                    endian: Endian::Little,
                    interfaces: Vec::new(),
                },
                failed: false,
            }),
            _ => Err(PcapError::BadMagic { magic: be }),
        }
    }

    /// Container format.
    pub fn format(&self) -> CaptureFormat {
        match self.state {
            State::Pcap { .. } => CaptureFormat::Pcap,
            State::PcapNg { .. } => CaptureFormat::PcapNg,
        }
    }

    /// Byte offset of the next record or block.
    pub fn position(&self) -> usize {
        self.pos
    }

    fn next_pcap(
        &mut self,
        endian: Endian,
        nanos: bool,
        linktype: u16,
    ) -> Result<Option<Record<'a>>, PcapError> {
        let at = self.pos;
        if at >= self.buf.len() {
            return Ok(None);
        }
        let h = slice(self.buf, at, 16, "pcap record header")?;
        let r = |i: usize| endian.u32([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        let (sec, frac, incl, orig) = (r(0), r(4), r(8), r(12));
        let data = slice(self.buf, at + 16, incl as usize, "pcap record data")?;
        let ns = u64::from(sec) * 1_000_000_000 + u64::from(frac) * if nanos { 1 } else { 1000 };
        self.pos = at + 16 + incl as usize;
        Ok(Some(Record {
            timestamp_ns: Some(ns),
            linktype,
            interface: 0,
            original_len: orig,
            data,
        }))
    }

    fn next_pcapng(&mut self) -> Result<Option<Record<'a>>, PcapError> {
        loop {
            let at = self.pos;
            if at >= self.buf.len() {
                return Ok(None);
            }
            let head = slice(self.buf, at, 8, "pcapng block header")?;
            let raw_type = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
            if raw_type == PCAPNG_SHB {
                // The SHB's byte-order magic decides the byte order of this section.
                let bom = slice(self.buf, at + 8, 4, "pcapng byte-order magic")?;
                let endian = if u32::from_le_bytes([bom[0], bom[1], bom[2], bom[3]])
                    == PCAPNG_BYTE_ORDER_MAGIC
                {
                    Endian::Little
                } else if u32::from_be_bytes([bom[0], bom[1], bom[2], bom[3]])
                    == PCAPNG_BYTE_ORDER_MAGIC
                {
                    Endian::Big
                } else {
                    return Err(PcapError::Invalid {
                        what: "byte-order magic",
                        block: "section header block",
                        offset: at,
                        value: u64::from(u32::from_le_bytes([bom[0], bom[1], bom[2], bom[3]])),
                    });
                };
                self.state = State::PcapNg {
                    endian,
                    interfaces: Vec::new(),
                };
            }
            let State::PcapNg { endian, interfaces } = &mut self.state else {
                return Ok(None);
            };
            let endian = *endian;
            let btype = rd32(endian, self.buf, at, "pcapng block type")?;
            let total = rd32(endian, self.buf, at + 4, "pcapng block length")? as usize;
            let name = block_name(btype);
            if total < 12 || !total.is_multiple_of(4) {
                return Err(PcapError::Invalid {
                    what: "block total length",
                    block: name,
                    offset: at,
                    value: total as u64,
                });
            }
            let block = slice(self.buf, at, total, name)?;
            let trailer = rd32(endian, block, total - 4, "pcapng trailing block length")? as usize;
            if trailer != total {
                return Err(PcapError::Invalid {
                    what: "trailing block length",
                    block: name,
                    offset: at,
                    value: trailer as u64,
                });
            }
            let body = &block[8..total - 4];
            self.pos = at + total;
            let b16 = |x: usize, what| rd16(endian, body, x, what).map_err(|e| at_block(e, at));
            let b32 = |x: usize, what| rd32(endian, body, x, what).map_err(|e| at_block(e, at));
            match btype {
                PCAPNG_IDB => {
                    let linktype = b16(0, "IDB link type")?;
                    let snaplen = b32(4, "IDB snap length")?;
                    let mut iface = Interface {
                        linktype,
                        snaplen,
                        tsresol: (false, 6),
                        tsoffset_s: 0,
                    };
                    for (code, val) in options(endian, body.get(8..).unwrap_or(&[])) {
                        match (code, val.len()) {
                            (9, 1..) => iface.tsresol = (val[0] & 0x80 != 0, val[0] & 0x7F),
                            (14, 8..) => {
                                let mut b = [0u8; 8];
                                b.copy_from_slice(&val[..8]);
                                iface.tsoffset_s = match endian {
                                    Endian::Little => i64::from_le_bytes(b),
                                    Endian::Big => i64::from_be_bytes(b),
                                };
                            }
                            _ => {}
                        }
                    }
                    interfaces.push(iface);
                }
                PCAPNG_EPB | PCAPNG_PB => {
                    let id = if btype == PCAPNG_EPB {
                        b32(0, "EPB interface id")?
                    } else {
                        u32::from(b16(0, "PB interface id")?)
                    };
                    let hi = b32(4, "timestamp")?;
                    let lo = b32(8, "timestamp")?;
                    let caplen = b32(12, "captured length")?;
                    let orig = b32(16, "original length")?;
                    let iface = interfaces.get(id as usize).copied().ok_or(
                        PcapError::UnknownInterface {
                            block: name,
                            offset: at,
                            interface: id,
                            known: interfaces.len(),
                        },
                    )?;
                    let data = body
                        .get(20..20usize.saturating_add(caplen as usize))
                        .ok_or(PcapError::Invalid {
                            what: "captured length",
                            block: name,
                            offset: at,
                            value: u64::from(caplen),
                        })?;
                    let ticks = (u64::from(hi) << 32) | u64::from(lo);
                    let ns = ticks_to_ns(ticks, iface.tsresol)
                        .saturating_add_signed(iface.tsoffset_s.saturating_mul(1_000_000_000));
                    return Ok(Some(Record {
                        timestamp_ns: Some(ns),
                        linktype: iface.linktype,
                        interface: id,
                        original_len: orig,
                        data,
                    }));
                }
                PCAPNG_SPB => {
                    let orig = b32(0, "SPB original length")?;
                    let iface = interfaces
                        .first()
                        .copied()
                        .ok_or(PcapError::UnknownInterface {
                            block: name,
                            offset: at,
                            interface: 0,
                            known: 0,
                        })?;
                    let room = body.len() - 4;
                    let mut caplen = (orig as usize).min(room);
                    if iface.snaplen != 0 {
                        caplen = caplen.min(iface.snaplen as usize);
                    }
                    let data = &body[4..4 + caplen];
                    return Ok(Some(Record {
                        timestamp_ns: None,
                        linktype: iface.linktype,
                        interface: 0,
                        original_len: orig,
                        data,
                    }));
                }
                _ => {} // SHB handled above; NRB, ISB, DSB, custom and unknown blocks skipped.
            }
        }
    }
}

fn at_block(e: PcapError, block_at: usize) -> PcapError {
    match e {
        PcapError::Truncated {
            what,
            offset,
            need,
            have,
        } => PcapError::Truncated {
            what,
            offset: block_at + 8 + offset,
            need,
            have,
        },
        other => other,
    }
}

fn block_name(t: u32) -> &'static str {
    match t {
        PCAPNG_SHB => "section header block",
        PCAPNG_IDB => "interface description block",
        PCAPNG_PB => "packet block",
        PCAPNG_SPB => "simple packet block",
        PCAPNG_EPB => "enhanced packet block",
        _ => "pcapng block",
    }
}

/// pcapng options: (code u16, length u16, value padded to 4) until code 0 or the end.
fn options(endian: Endian, mut b: &[u8]) -> impl Iterator<Item = (u16, &[u8])> {
    std::iter::from_fn(move || {
        let code = endian.u16([*b.first()?, *b.get(1)?]);
        let len = usize::from(endian.u16([*b.get(2)?, *b.get(3)?]));
        if code == 0 {
            return None;
        }
        let val = b.get(4..4 + len)?;
        let padded = 4 + len.div_ceil(4) * 4;
        b = b.get(padded..).unwrap_or(&[]);
        Some((code, val))
    })
}

impl<'a> Iterator for CaptureReader<'a> {
    type Item = Result<Record<'a>, PcapError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        let r = match self.state {
            State::Pcap {
                endian,
                nanos,
                linktype,
            } => self.next_pcap(endian, nanos, linktype),
            State::PcapNg { .. } => self.next_pcapng(),
        };
        match r {
            Ok(Some(rec)) => Some(Ok(rec)),
            Ok(None) => None,
            Err(e) => {
                self.failed = true;
                Some(Err(e))
            }
        }
    }
}

/// An owned record, for callers that read a whole file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OwnedRecord {
    /// Capture time in ns since the Unix epoch, if the format carries one.
    pub timestamp_ns: Option<u64>,
    /// Link type.
    pub linktype: u16,
    /// Captured bytes.
    pub data: Vec<u8>,
}

/// Read every record of a capture file.
pub fn read_file(path: impl AsRef<Path>) -> Result<Vec<OwnedRecord>, PcapError> {
    let bytes = crate::limits::read_file(
        path.as_ref(),
        "capture file",
        crate::limits::MAX_CAPTURE_FILE_BYTES,
    )?;
    CaptureReader::new(&bytes)?
        .map(|r| {
            r.map(|r| OwnedRecord {
                timestamp_ns: r.timestamp_ns,
                linktype: r.linktype,
                data: r.data.to_vec(),
            })
        })
        .collect()
}

/// Timestamp resolution of a classic pcap file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimestampResolution {
    /// Microseconds (magic 0xA1B2C3D4), readable by every tool.
    Micro,
    /// Nanoseconds (magic 0xA1B23C4D).
    Nano,
}

/// Writer of classic little-endian pcap files with `LINKTYPE_ETHERNET`.
#[derive(Debug)]
pub struct PcapWriter<W: Write> {
    out: W,
    resolution: TimestampResolution,
    snaplen: u32,
}

impl<W: Write> PcapWriter<W> {
    /// Write the file header. Snap length 65535.
    pub fn new(out: W, resolution: TimestampResolution) -> Result<Self, PcapError> {
        Self::with_snaplen(out, resolution, 65_535)
    }

    /// Write the file header with a given snap length; longer packets are cut.
    pub fn with_snaplen(
        mut out: W,
        resolution: TimestampResolution,
        snaplen: u32,
    ) -> Result<Self, PcapError> {
        let magic = match resolution {
            TimestampResolution::Micro => PCAP_MAGIC_US,
            TimestampResolution::Nano => PCAP_MAGIC_NS,
        };
        let mut h = Vec::with_capacity(24);
        h.extend_from_slice(&magic.to_le_bytes());
        h.extend_from_slice(&2u16.to_le_bytes());
        h.extend_from_slice(&4u16.to_le_bytes());
        h.extend_from_slice(&0i32.to_le_bytes()); // thiszone
        h.extend_from_slice(&0u32.to_le_bytes()); // sigfigs
        h.extend_from_slice(&snaplen.to_le_bytes());
        h.extend_from_slice(&u32::from(LINKTYPE_ETHERNET).to_le_bytes());
        out.write_all(&h)?;
        Ok(PcapWriter {
            out,
            resolution,
            snaplen,
        })
    }

    /// Append one packet captured at `timestamp_ns` (ns since the Unix epoch; seconds beyond
    /// 32 bits are rejected).
    pub fn write_packet(&mut self, timestamp_ns: u64, data: &[u8]) -> Result<(), PcapError> {
        let sec = timestamp_ns / 1_000_000_000;
        let sub = timestamp_ns % 1_000_000_000;
        let sec = u32::try_from(sec).map_err(|_| PcapError::Invalid {
            what: "timestamp seconds",
            block: "pcap record",
            offset: 0,
            value: sec,
        })?;
        let frac = match self.resolution {
            TimestampResolution::Micro => sub / 1000,
            TimestampResolution::Nano => sub,
        } as u32;
        let orig = u32::try_from(data.len()).unwrap_or(u32::MAX);
        let incl = orig.min(self.snaplen);
        let mut h = [0u8; 16];
        h[0..4].copy_from_slice(&sec.to_le_bytes());
        h[4..8].copy_from_slice(&frac.to_le_bytes());
        h[8..12].copy_from_slice(&incl.to_le_bytes());
        h[12..16].copy_from_slice(&orig.to_le_bytes());
        self.out.write_all(&h)?;
        self.out.write_all(&data[..incl as usize])?;
        Ok(())
    }

    /// Flush the underlying writer.
    pub fn flush(&mut self) -> Result<(), PcapError> {
        self.out.flush()?;
        Ok(())
    }

    /// Flush and return the underlying writer.
    pub fn into_inner(mut self) -> Result<W, PcapError> {
        self.out.flush()?;
        Ok(self.out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tsresol_conversion() {
        assert_eq!(ticks_to_ns(1_500_000, (false, 6)), 1_500_000_000);
        assert_eq!(ticks_to_ns(7, (false, 9)), 7);
        assert_eq!(ticks_to_ns(1 << 20, (true, 20)), 1_000_000_000);
        assert_eq!(ticks_to_ns(u64::MAX, (false, 0)), u64::MAX);
        assert_eq!(ticks_to_ns(123, (true, 127)), 0);
    }
}
