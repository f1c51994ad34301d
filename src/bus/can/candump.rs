//! `candump -L` log lines (can-utils `lib.c` `snprintf_canframe` / `parse_canframe`; the format
//! `canplayer` replays and `log2asc` converts):
//!
//! ```text
//! (1700000000.123456) can0 601#4041100000000000     standard data frame, 8 bytes
//! (1700000000.123456) can0 12345678#DEADBEEF        extended (8 hex digits), 4 bytes
//! (1700000000.123456) can0 123#R                    remote frame, length 0
//! (1700000000.123456) can0 123#R8                   remote frame asking for 8 bytes
//! (1700000000.123456) can0 20000040#0000000000000000  error frame: CAN_ERR_FLAG | bus-off
//! ```
//!
//! Writing follows can-utils: upper-case hex, 3 digits for a standard and 8 for an extended
//! identifier, the error frame's identifier word with `CAN_ERR_FLAG` and its 8 data bytes, the
//! timestamp with 6 decimals. Parsing also accepts lower-case hex, `.` between data bytes, the
//! raw-DLC suffix `_D` of 8-byte frames (ignored), and a trailing `R`/`T` direction marker.
//! CAN FD lines (`##`) are refused: this crate carries classic CAN only.
//!
//! # Interface names
//!
//! `canplayer` sends each line on the interface the line names (or the one `-t` / an
//! assignment `vcan0=can0` maps it to) and refuses a name of [`IFNAMSIZ`] bytes or more
//! ("interface name too long"); the kernel takes no name with `/`, `:` or blanks
//! (`dev_valid_name`). So every log this crate writes names the interface as the kernel does:
//! `vcan0` for `socketcan:vcan0`; a bus that is no kernel interface gets a short stand-in,
//! [`UDP_INTERFACE`] for python-can's `udp_multicast`, [`EMU_INTERFACE`] for the in-process
//! virtual bus (`canopen-emu`); [`CandumpWriter::new`] makes any other name fit
//! ([`interface_name`]). The reader takes any name without blanks, so logs written before this
//! rule (`socketcan_vcan0`, `udp_239.74.163.2:43113`, `vcan-emu`) still read.

use std::{
    io::{self, Write},
    time::{Duration, SystemTime, UNIX_EPOCH},
};

use super::{CanFrame, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_ERR_MASK, CAN_SFF_MASK};

/// One parsed log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CandumpRecord {
    /// Time since the UNIX epoch (microsecond resolution in the file).
    pub timestamp: Duration,
    /// Interface name (`can0`, `vcan0`).
    pub interface: String,
    /// The frame.
    pub frame: CanFrame,
}

/// Why a log line was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("candump line `{line}`: {why}")]
pub struct CandumpError {
    /// The line (trimmed).
    pub line: String,
    /// What is wrong with it.
    pub why: String,
}

/// `IFNAMSIZ` of `linux/if.h`: an interface name has at most `IFNAMSIZ - 1` bytes.
pub const IFNAMSIZ: usize = 16;

/// Interface name in logs of python-can's `udp_multicast` bus (`canopen-udp`, `sim canopen
/// --bus udp`): no kernel interface, so a stand-in `canplayer` takes (`-t … vcan0=udp0`).
pub const UDP_INTERFACE: &str = "udp0";

/// Interface name in logs of the in-process virtual bus (`canopen-emu`).
pub const EMU_INTERFACE: &str = "emu0";

/// Is `name` an interface name the kernel and `canplayer` take: 1 … `IFNAMSIZ - 1` bytes, not
/// `.` or `..`, none of `/`, `:` or whitespace (`net/core/dev.c` `dev_valid_name`)?
pub fn is_interface_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() < IFNAMSIZ
        && name != "."
        && name != ".."
        && !name
            .chars()
            .any(|c| c == '/' || c == ':' || c.is_whitespace())
}

/// `name` made into an interface name ([`is_interface_name`]): a valid name stays as it is;
/// otherwise every character other than ASCII letters, digits, `_` and `-` becomes `_` and
/// the result is cut to `IFNAMSIZ - 1` bytes; nothing left gives `can0`.
pub fn interface_name(name: &str) -> String {
    if is_interface_name(name) {
        return name.to_string();
    }
    let mut s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .take(IFNAMSIZ - 1)
        .collect();
    if s.chars().all(|c| c == '_') {
        s = "can0".into();
    }
    s
}

fn hex_upper(out: &mut String, bytes: &[u8]) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    for b in bytes {
        out.push(HEX[usize::from(b >> 4)] as char);
        out.push(HEX[usize::from(b & 0xF)] as char);
    }
}

/// The frame part (`601#4041…`, `123#R`, `20000040#…`) as can-utils writes it.
pub fn format_frame(frame: &CanFrame) -> String {
    let mut s = String::with_capacity(26);
    if frame.error {
        s.push_str(&format!(
            "{:08X}#",
            (frame.id & CAN_ERR_MASK) | CAN_ERR_FLAG
        ));
        hex_upper(&mut s, frame.payload());
        return s;
    }
    if frame.extended {
        s.push_str(&format!("{:08X}#", frame.id & CAN_EFF_MASK));
    } else {
        s.push_str(&format!("{:03X}#", frame.id & CAN_SFF_MASK));
    }
    if frame.rtr {
        s.push('R');
        if (1..=8).contains(&frame.len) {
            s.push(char::from(b'0' + frame.len));
        }
    } else {
        hex_upper(&mut s, frame.payload());
    }
    s
}

/// A whole `candump -L` line (without newline).
pub fn format_line(timestamp: Duration, interface: &str, frame: &CanFrame) -> String {
    format!(
        "({}.{:06}) {} {}",
        timestamp.as_secs(),
        timestamp.subsec_micros(),
        interface,
        format_frame(frame)
    )
}

fn hex_val(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

/// Parse the frame part (`601#4041…`).
pub fn parse_frame(s: &str) -> Result<CanFrame, String> {
    if s.contains("##") {
        return Err("CAN FD frame (`##`); only classic CAN is supported".into());
    }
    let (id_s, rest) = s
        .split_once('#')
        .ok_or_else(|| format!("`{s}` has no `#` between identifier and data"))?;
    if !id_s.bytes().all(|c| hex_val(c).is_some()) || !matches!(id_s.len(), 3 | 8) {
        return Err(format!(
            "identifier `{id_s}` is not 3 (standard) or 8 (extended) hex digits"
        ));
    }
    let word = u32::from_str_radix(id_s, 16).map_err(|e| format!("identifier `{id_s}`: {e}"))?;
    let mut frame = CanFrame {
        id: 0,
        extended: false,
        rtr: false,
        error: false,
        len: 0,
        data: [0; 8],
    };
    if id_s.len() == 3 {
        if word > CAN_SFF_MASK {
            return Err(format!("standard identifier {word:#05x} > 0x7FF"));
        }
        frame.id = word;
    } else if word & CAN_ERR_FLAG != 0 {
        if word & !(CAN_ERR_FLAG | CAN_ERR_MASK) != 0 {
            return Err(format!(
                "error frame identifier {word:#010x} has EFF/RTR flags set"
            ));
        }
        frame.error = true;
        frame.id = word & CAN_ERR_MASK;
    } else {
        if word > CAN_EFF_MASK {
            return Err(format!("extended identifier {word:#010x} > 0x1FFFFFFF"));
        }
        frame.id = word;
        frame.extended = true;
    }
    let bytes = rest.as_bytes();
    if matches!(bytes.first(), Some(b'R' | b'r')) {
        if frame.error {
            return Err("error frame marked remote".into());
        }
        frame.rtr = true;
        match &bytes[1..] {
            [] => {}
            [d] if (b'0'..=b'8').contains(d) => frame.len = d - b'0',
            other => {
                return Err(format!(
                    "remote frame length `{}` is not one digit 0 … 8",
                    String::from_utf8_lossy(other)
                ))
            }
        }
        return Ok(frame);
    }
    let (data_s, dlc_suffix) = match rest.split_once('_') {
        Some((d, x)) => (d, Some(x)),
        None => (rest, None),
    };
    let mut n = 0usize;
    let mut it = data_s.bytes().filter(|c| *c != b'.');
    while let Some(hi) = it.next() {
        let lo = it
            .next()
            .ok_or_else(|| format!("odd number of hex digits in data `{data_s}`"))?;
        let (Some(h), Some(l)) = (hex_val(hi), hex_val(lo)) else {
            return Err(format!("data `{data_s}` is not hex"));
        };
        if n == 8 {
            return Err(format!("data `{data_s}` has more than 8 bytes"));
        }
        frame.data[n] = (h << 4) | l;
        n += 1;
    }
    if let Some(x) = dlc_suffix {
        let ok = n == 8 && x.len() == 1 && x.bytes().all(|c| hex_val(c).is_some_and(|v| v > 8));
        if !ok {
            return Err(format!(
                "raw DLC suffix `_{x}` (allowed only after 8 data bytes, 9 … F)"
            ));
        }
    }
    frame.len = n as u8;
    Ok(frame)
}

/// Parse one `candump -L` line: `(SECS.USECS) IFACE FRAME` (leading/trailing blanks allowed).
pub fn parse_line(line: &str) -> Result<CandumpRecord, CandumpError> {
    let t = line.trim();
    let err = |why: String| CandumpError {
        line: t.to_string(),
        why,
    };
    let mut parts = t.split_ascii_whitespace();
    let (Some(ts), Some(iface), Some(frame)) = (parts.next(), parts.next(), parts.next()) else {
        return Err(err("expected `(SECS.USECS) IFACE FRAME`".into()));
    };
    match parts.next() {
        None | Some("R") | Some("T") => {}
        Some(x) => return Err(err(format!("unexpected `{x}` after the frame"))),
    }
    if parts.next().is_some() {
        return Err(err("unexpected text after the frame".into()));
    }
    let inner = ts
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| err(format!("timestamp `{ts}` is not `(SECS.USECS)`")))?;
    let (secs, frac) = inner
        .split_once('.')
        .ok_or_else(|| err(format!("timestamp `{ts}` has no `.`")))?;
    if secs.is_empty()
        || frac.is_empty()
        || frac.len() > 9
        || !secs.bytes().chain(frac.bytes()).all(|c| c.is_ascii_digit())
    {
        return Err(err(format!("timestamp `{ts}` is not `(SECS.USECS)`")));
    }
    let secs: u64 = secs
        .parse()
        .map_err(|e| err(format!("timestamp seconds `{secs}`: {e}")))?;
    let nanos: u32 = format!("{frac:0<9}")
        .parse()
        .map_err(|e| err(format!("timestamp fraction `{frac}`: {e}")))?;
    let frame = parse_frame(frame).map_err(err)?;
    Ok(CandumpRecord {
        timestamp: Duration::new(secs, nanos),
        interface: iface.to_string(),
        frame,
    })
}

/// Writes frames as `candump -L` lines.
#[derive(Debug)]
pub struct CandumpWriter<W: Write> {
    out: W,
    interface: String,
}

impl<W: Write> CandumpWriter<W> {
    /// Log to `out` under interface name `interface`, made to fit the kernel's rules by
    /// [`interface_name`] (module documentation).
    pub fn new(out: W, interface: &str) -> CandumpWriter<W> {
        CandumpWriter {
            out,
            interface: interface_name(interface),
        }
    }

    /// The interface name the lines carry.
    pub fn interface(&self) -> &str {
        &self.interface
    }

    /// Log `frame` at `timestamp` (since the UNIX epoch).
    pub fn write_frame(&mut self, timestamp: Duration, frame: &CanFrame) -> io::Result<()> {
        writeln!(
            self.out,
            "{}",
            format_line(timestamp, &self.interface, frame)
        )
    }

    /// Log `frame` at the current wall-clock time.
    pub fn write_frame_now(&mut self, frame: &CanFrame) -> io::Result<()> {
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default();
        self.write_frame(now, frame)
    }

    /// Flush the output.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// Unwrap the output.
    pub fn into_inner(self) -> W {
        self.out
    }
}
