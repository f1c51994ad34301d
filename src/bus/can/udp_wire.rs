//! python-can `udp_multicast` datagram codec (python-can 4.6.1
//! `can/interfaces/udp_multicast/utils.py`).
//!
//! One CAN frame is one UDP datagram holding one msgpack map, written by
//! `msgpack.packb(message_as_dict, use_bin_type=True)` with the keys in this order:
//!
//! | key | msgpack type | here |
//! |---|---|---|
//! | `timestamp` | float 64 (`0xcb`) | sender's choice; python-can replaces it with its receive time |
//! | `arbitration_id` | int, smallest encoding | [`CanFrame::id`] (error class bits for error frames) |
//! | `is_extended_id` | bool | [`CanFrame::extended`] |
//! | `is_remote_frame` | bool | [`CanFrame::rtr`] |
//! | `is_error_frame` | bool | [`CanFrame::error`] |
//! | `channel` | nil | |
//! | `dlc` | int | **byte count** 0 … 8 (not the FD DLC code); the requested length of a remote frame |
//! | `data` | bin | the payload; empty for a remote frame |
//! | `is_fd`, `bitrate_switch`, `error_state_indicator` | bool | always false |
//!
//! python-can decodes with `Message(check=True, **dict)`: an unknown key, `dlc` ≠ data length,
//! a standard identifier ≥ 0x800 or data in a remote frame make its `recv()` raise (and stop a
//! `can.Notifier`). [`encode`] therefore refuses every frame python-can would refuse.
//! [`decode`] is lenient where python-can is lenient or where leniency is harmless (unknown keys
//! are skipped, missing keys take python-can's defaults, `data` may be an int array) and
//! returns [`CanError::Malformed`] where python-can would refuse the message; it never panics.

use super::{CanError, CanFrame, CAN_EFF_MASK, CAN_SFF_MASK};

/// Largest datagram python-can reads (`max_buffer = 4096` in `udp_multicast/bus.py`).
pub const PYTHON_CAN_MAX_BUFFER: usize = 4096;

/// Key order of python-can's `Message` dict (`utils.py` `pack_message`).
pub const KEYS: [&str; 11] = [
    "timestamp",
    "arbitration_id",
    "is_extended_id",
    "is_remote_frame",
    "is_error_frame",
    "channel",
    "dlc",
    "data",
    "is_fd",
    "bitrate_switch",
    "error_state_indicator",
];

fn put_str(out: &mut Vec<u8>, s: &str) {
    // All keys are shorter than 32 bytes: fixstr 0xa0 | len.
    debug_assert!(s.len() < 32);
    out.push(0xa0 | s.len() as u8);
    out.extend_from_slice(s.as_bytes());
}

fn put_bool(out: &mut Vec<u8>, b: bool) {
    out.push(if b { 0xc3 } else { 0xc2 });
}

/// Non-negative integer in msgpack's smallest encoding (what msgpack-python writes).
fn put_uint(out: &mut Vec<u8>, v: u32) {
    match v {
        0..=0x7f => out.push(v as u8),
        0x80..=0xff => out.extend_from_slice(&[0xcc, v as u8]),
        0x100..=0xffff => {
            out.push(0xcd);
            out.extend_from_slice(&(v as u16).to_be_bytes());
        }
        _ => {
            out.push(0xce);
            out.extend_from_slice(&v.to_be_bytes());
        }
    }
}

/// Append the datagram for `frame` to `out`, with `timestamp` (seconds) in the `timestamp` field.
///
/// Fails with [`CanError::Frame`] for a frame python-can would refuse: identifier out of range
/// for its format, `len` > 8, or both remote and error frame. Bytes beyond `len` are not sent.
pub fn encode(frame: &CanFrame, timestamp: f64, out: &mut Vec<u8>) -> Result<(), CanError> {
    frame.validate()?;
    // python-can checks the identifier range by `is_extended_id` also for error frames.
    if frame.error && !frame.extended && frame.id > CAN_SFF_MASK {
        return Err(super::FrameError::Id { id: frame.id }.into());
    }
    out.push(0x80 | KEYS.len() as u8);
    put_str(out, KEYS[0]);
    out.push(0xcb);
    out.extend_from_slice(&timestamp.to_bits().to_be_bytes());
    put_str(out, KEYS[1]);
    put_uint(out, frame.id);
    put_str(out, KEYS[2]);
    put_bool(out, frame.extended);
    put_str(out, KEYS[3]);
    put_bool(out, frame.rtr);
    put_str(out, KEYS[4]);
    put_bool(out, frame.error);
    put_str(out, KEYS[5]);
    out.push(0xc0);
    put_str(out, KEYS[6]);
    put_uint(out, u32::from(frame.len));
    put_str(out, KEYS[7]);
    let data: &[u8] = if frame.rtr { &[] } else { frame.payload() };
    out.extend_from_slice(&[0xc4, data.len() as u8]);
    out.extend_from_slice(data);
    for key in &KEYS[8..] {
        put_str(out, key);
        put_bool(out, false);
    }
    Ok(())
}

/// One msgpack item header (containers are not descended into).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Item<'a> {
    Nil,
    Bool(bool),
    Int(i128),
    Float(f64),
    Str(&'a [u8]),
    Bin(&'a [u8]),
    Array(u64),
    Map(u64),
    Ext,
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

fn malformed(what: impl Into<String>) -> CanError {
    CanError::Malformed(what.into())
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: u64) -> Result<&'a [u8], CanError> {
        let left = (self.buf.len() - self.pos) as u64;
        if n > left {
            return Err(malformed(format!(
                "msgpack item needs {n} bytes at offset {}, {left} left",
                self.pos
            )));
        }
        let s = &self.buf[self.pos..self.pos + n as usize];
        self.pos += n as usize;
        Ok(s)
    }

    fn be(&mut self, n: u64) -> Result<u64, CanError> {
        Ok(self
            .take(n)?
            .iter()
            .fold(0u64, |acc, b| (acc << 8) | u64::from(*b)))
    }

    fn item(&mut self) -> Result<Item<'a>, CanError> {
        let at = self.pos;
        let t = self.take(1)?[0];
        Ok(match t {
            0x00..=0x7f => Item::Int(i128::from(t)),
            0x80..=0x8f => Item::Map(u64::from(t & 0x0f)),
            0x90..=0x9f => Item::Array(u64::from(t & 0x0f)),
            0xa0..=0xbf => Item::Str(self.take(u64::from(t & 0x1f))?),
            0xc0 => Item::Nil,
            0xc2 => Item::Bool(false),
            0xc3 => Item::Bool(true),
            0xc4..=0xc6 => {
                let n = self.be(1 << (t - 0xc4))?;
                Item::Bin(self.take(n)?)
            }
            0xc7..=0xc9 => {
                let n = self.be(1 << (t - 0xc7))?;
                self.take(1 + n)?;
                Item::Ext
            }
            0xca => Item::Float(f64::from(f32::from_bits(self.be(4)? as u32))),
            0xcb => Item::Float(f64::from_bits(self.be(8)?)),
            0xcc..=0xcf => Item::Int(i128::from(self.be(1 << (t - 0xcc))?)),
            0xd0 => Item::Int(i128::from(self.be(1)? as u8 as i8)),
            0xd1 => Item::Int(i128::from(self.be(2)? as u16 as i16)),
            0xd2 => Item::Int(i128::from(self.be(4)? as u32 as i32)),
            0xd3 => Item::Int(i128::from(self.be(8)? as i64)),
            0xd4..=0xd8 => {
                self.take(1 + (1u64 << (t - 0xd4)))?;
                Item::Ext
            }
            0xd9..=0xdb => {
                let n = self.be(1 << (t - 0xd9))?;
                Item::Str(self.take(n)?)
            }
            0xdc | 0xdd => Item::Array(self.be(2 << (t - 0xdc))?),
            0xde | 0xdf => Item::Map(self.be(2 << (t - 0xde))?),
            0xe0..=0xff => Item::Int(i128::from(t as i8)),
            0xc1 => return Err(malformed(format!("msgpack type byte 0xc1 at offset {at}"))),
        })
    }

    /// Skip one complete value (containers included), without recursion.
    fn skip_value_after(&mut self, first: Item<'a>) -> Result<(), CanError> {
        let mut pending: u64 = match first {
            Item::Array(n) => n,
            Item::Map(n) => n.saturating_mul(2),
            _ => 0,
        };
        while pending > 0 {
            pending -= 1;
            match self.item()? {
                Item::Array(n) => pending = pending.saturating_add(n),
                Item::Map(n) => pending = pending.saturating_add(n.saturating_mul(2)),
                _ => {}
            }
        }
        Ok(())
    }
}

fn as_bool(key: &str, it: Item<'_>) -> Result<bool, CanError> {
    match it {
        Item::Bool(b) => Ok(b),
        Item::Nil => Ok(false),
        Item::Int(i) => Ok(i != 0),
        other => Err(malformed(format!("`{key}` is {other:?}, expected a bool"))),
    }
}

/// Decode one datagram.
///
/// `Ok(None)`: a well-formed CAN FD message (`is_fd` true), which a classic bus ignores as
/// python-can with `fd=False` does. Missing keys take python-can's `Message` defaults
/// (`arbitration_id` 0, **`is_extended_id` true**, flags false, `data` empty, `dlc` = data
/// length). The `timestamp` is ignored.
pub fn decode(datagram: &[u8]) -> Result<Option<CanFrame>, CanError> {
    let mut r = Reader {
        buf: datagram,
        pos: 0,
    };
    let n = match r.item()? {
        Item::Map(n) => n,
        other => {
            return Err(malformed(format!(
                "datagram is {other:?}, not a msgpack map"
            )))
        }
    };
    let mut id: i128 = 0;
    let mut extended = true;
    let mut rtr = false;
    let mut error = false;
    let mut fd = false;
    let mut dlc: Option<i128> = None;
    let mut data = [0u8; 8];
    let mut data_len: usize = 0;
    for _ in 0..n {
        let key_item = r.item()?;
        let key = match key_item {
            Item::Str(k) => k,
            other => {
                // Not a python keyword argument: skip key and value.
                r.skip_value_after(other)?;
                let v = r.item()?;
                r.skip_value_after(v)?;
                continue;
            }
        };
        let value = r.item()?;
        match key {
            b"arbitration_id" => match value {
                Item::Int(i) => id = i,
                other => {
                    return Err(malformed(format!(
                        "`arbitration_id` is {other:?}, expected an int"
                    )))
                }
            },
            b"is_extended_id" => extended = as_bool("is_extended_id", value)?,
            b"is_remote_frame" => rtr = as_bool("is_remote_frame", value)?,
            b"is_error_frame" => error = as_bool("is_error_frame", value)?,
            b"is_fd" => fd = as_bool("is_fd", value)?,
            b"dlc" => match value {
                Item::Int(i) => dlc = Some(i),
                Item::Nil => dlc = None,
                other => return Err(malformed(format!("`dlc` is {other:?}, expected an int"))),
            },
            b"data" => {
                // A repeated key replaces the earlier value, as in a Python dict.
                data = [0; 8];
                match value {
                    Item::Nil => data_len = 0,
                    Item::Bin(b) => {
                        if b.len() > 64 {
                            return Err(malformed(format!("{} data bytes (at most 64)", b.len())));
                        }
                        if !fd && b.len() <= 8 {
                            data[..b.len()].copy_from_slice(b);
                        }
                        data_len = b.len();
                    }
                    Item::Array(k) => {
                        if k > 64 {
                            return Err(malformed(format!("{k} data bytes (at most 64)")));
                        }
                        for i in 0..k as usize {
                            let v = match r.item()? {
                                Item::Int(v @ 0..=255) => v as u8,
                                other => {
                                    return Err(malformed(format!(
                                        "data[{i}] is {other:?}, expected a byte"
                                    )))
                                }
                            };
                            if let Some(slot) = data.get_mut(i) {
                                *slot = v;
                            }
                        }
                        data_len = k as usize;
                    }
                    other => {
                        return Err(malformed(format!(
                            "`data` is {other:?}, expected bin or an int array"
                        )))
                    }
                }
            }
            _ => r.skip_value_after(value)?,
        }
    }
    if r.pos != datagram.len() {
        return Err(malformed(format!(
            "{} bytes after the msgpack map",
            datagram.len() - r.pos
        )));
    }
    if rtr && error {
        return Err(malformed("both remote and error frame"));
    }
    if rtr && data_len > 0 {
        return Err(malformed("remote frame carrying data"));
    }
    let len = match dlc {
        None => data_len as i128,
        Some(d) => d,
    };
    if !rtr && len != data_len as i128 {
        return Err(malformed(format!("dlc {len} but {data_len} data bytes")));
    }
    let max_id = if extended { CAN_EFF_MASK } else { CAN_SFF_MASK };
    if !(0..=i128::from(max_id)).contains(&id) {
        return Err(malformed(format!(
            "arbitration_id {id:#x} out of range for a {} identifier",
            if extended { "29-bit" } else { "11-bit" }
        )));
    }
    if fd {
        if rtr {
            return Err(malformed("CAN FD remote frame"));
        }
        if !(0..=64).contains(&len) {
            return Err(malformed(format!("CAN FD dlc {len} (0 … 64)")));
        }
        return Ok(None);
    }
    if !(0..=8).contains(&len) {
        return Err(malformed(format!("dlc {len} (classic CAN: 0 … 8)")));
    }
    let len = len as u8;
    if rtr {
        data = [0; 8];
    }
    Ok(Some(CanFrame {
        id: id as u32,
        extended,
        rtr,
        error,
        len,
        data,
    }))
}
