//! SoE (Servo drive profile over EtherCAT, mailbox type 5) client on ethercrab's public raw
//! commands, through the shared [`MailboxTransport`] (ethercrab 0.7.1 has no SoE; notes
//! `ethercat.md` §7.3).
//!
//! Wire layout (ETG.1000.6 SoE, as SOEM's `ec_soe.c` lays it out): mailbox header, SoE header
//! ([`SoeHeader`]: opcode 3 bits, incomplete, error, drive number 3 bits; element flags; IDN or
//! fragments left), data. [`SoeClient`] groups:
//!
//! * element access: [`SoeClient::read_idn`] (opcode 1 → 2; fragmented replies — incomplete
//!   bit set, IDN field = fragments left, the fragments arrive one after the other in the read
//!   mailbox without further requests — are joined), [`SoeClient::write_idn`] (opcode 3 → 4;
//!   data longer than the write mailbox are sent as fragments, only the last one is answered);
//! * typed helpers: [`SoeClient::read_name`], [`SoeClient::read_attribute`],
//!   [`SoeClient::read_value`] / [`SoeClient::write_value`] (length and signedness from the
//!   attribute, [`IdnAttribute`]).
//!
//! An error reply (error bit, 2-byte SERCOS error code) becomes [`MailboxError::Soe`] with the
//! code in words ([`error_text`]). CoE emergencies arriving meanwhile are collected by the
//! transport ([`SoeClient::take_emergencies`]); SoE notifications / slave-info messages (opcodes
//! 5 / 6) are skipped.

use std::time::Duration;

use ethercrab::MainDevice;

use super::mailbox::{Emergency, MailboxError, MailboxTransport};
use super::wire::{MailboxType, SoeHeader, SoeOpcode};
use crate::drive::sercos::{idn_code, idn_name};

/// IDN code of a name like `S-0-0092` / `P-0-0010` (bit 15 P, bits 12–14 parameter set, bits
/// 0–11 number; `S-0-0092` = 0x005C, `P-0-0010` = 0x800A). Same parser as the drive
/// definitions ([`crate::drive::sercos::idn_code`]).
pub fn parse_idn(text: &str) -> Option<u16> {
    idn_code(text)
}

/// Name of an IDN code (`0x005C` → `S-0-0092`; [`crate::drive::sercos::idn_name`]).
pub fn format_idn(idn: u16) -> String {
    idn_name(idn)
}

/// SERCOS error code of an SoE error reply in words (IEC 61800-7-204 error codes as listed by
/// SOEM / IgH; the codes the emulator (`sim::esc::soe::error`) answers with are among them).
pub fn error_text(code: u16) -> &'static str {
    match code {
        0x0000 => "no error",
        0x0009 => "invalid access to element 0",
        0x1001 => "IDN does not exist",
        0x1009 => "invalid access to element 1 (element not supported)",
        0x2001 => "name does not exist",
        0x2002 => "name transmission too short",
        0x2003 => "name transmission too long",
        0x2004 => "name cannot be changed (read only)",
        0x2005 => "name is write protected at this time",
        0x3002 => "attribute transmission too short",
        0x3003 => "attribute transmission too long",
        0x3004 => "attribute cannot be changed (read only)",
        0x3005 => "attribute is write protected at this time",
        0x4001 => "unit does not exist",
        0x4002 => "unit transmission too short",
        0x4003 => "unit transmission too long",
        0x4004 => "unit cannot be changed (read only)",
        0x4005 => "unit is write protected at this time",
        0x5001 => "minimum input value does not exist",
        0x5002 => "minimum input value transmission too short",
        0x5003 => "minimum input value transmission too long",
        0x5004 => "minimum input value cannot be changed (read only)",
        0x5005 => "minimum input value is write protected at this time",
        0x6001 => "maximum input value does not exist",
        0x6002 => "maximum input value transmission too short",
        0x6003 => "maximum input value transmission too long",
        0x6004 => "maximum input value cannot be changed (read only)",
        0x6005 => "maximum input value is write protected at this time",
        0x7002 => "data transmission too short",
        0x7003 => "data transmission too long",
        0x7004 => "data cannot be changed (read only)",
        0x7005 => "data is write protected at this time (communication phase / state)",
        0x7006 => "data smaller than the minimum input value",
        0x7007 => "data greater than the maximum input value",
        0x7008 => "invalid data",
        0x7009 => "data write protected by a password",
        0x700A => "data write protected, it is configured cyclically",
        0x700B => "invalid indirect addressing (data container, list handling)",
        0x700C => "data write protected due to other settings",
        0x7010 => "procedure command already active",
        0x7011 => "procedure command not interruptible",
        0x7012 => "procedure command not executable at this time (state)",
        0x7013 => "procedure command not executable (invalid or false parameters)",
        0x7014 => "no data state",
        0x8001 => "default value does not exist",
        0x8002 => "default value transmission too long",
        0x8004 => "default value cannot be changed (read only)",
        0x800A => "invalid drive number",
        0x800B => "general error",
        0x800C => "no element addressed",
        _ => "unknown SoE error code",
    }
}

/// Element of an IDN, with its SoE element flag (ETG.1000.6 SoE header).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Element {
    /// 0x01 data state.
    DataState,
    /// 0x02 name (SERCOS string: current length u16, maximum length u16, characters).
    Name,
    /// 0x04 attribute (u32, [`IdnAttribute`]).
    Attribute,
    /// 0x08 unit.
    Unit,
    /// 0x10 minimum input value.
    Minimum,
    /// 0x20 maximum input value.
    Maximum,
    /// 0x40 value (operation data).
    Value,
    /// 0x80 default value.
    Default,
}

impl Element {
    /// Element flag of the SoE header.
    pub const fn flag(self) -> u8 {
        match self {
            Element::DataState => 0x01,
            Element::Name => 0x02,
            Element::Attribute => 0x04,
            Element::Unit => 0x08,
            Element::Minimum => 0x10,
            Element::Maximum => 0x20,
            Element::Value => 0x40,
            Element::Default => 0x80,
        }
    }
}

/// Data type of an IDN (attribute bits 20–22; IEC 61800-7-204).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum IdnDataType {
    /// 0 binary.
    Binary,
    /// 1 unsigned integer.
    Unsigned,
    /// 2 signed integer.
    Signed,
    /// 3 unsigned integer shown hexadecimal.
    Hex,
    /// 4 text (string).
    Text,
    /// 5 IDN.
    Idn,
    /// 6 floating point.
    Float,
    /// 7 parameter (SERCOS III: reserved / vendor).
    Parameter,
}

/// Decoded attribute element of an IDN (IEC 61800-7-204 attribute, as in
/// SOEM `ec_SoEattributet`):
///
/// | bits | field |
/// |---|---|
/// | 0–15 | conversion (evaluation) factor |
/// | 16–17 | data length: 0 = 1 byte, 1 = 2, 2 = 4, 3 = 8 (SOEM: `8 << length` bits) |
/// | 18 | list (variable length: current length u16, maximum length u16, items) |
/// | 19 | procedure command |
/// | 20–22 | data type ([`IdnDataType`]) |
/// | 24–27 | decimal places |
/// | 28 / 29 / 30 | write protected in PRE-OP (CP2) / SAFE-OP (CP3) / OP (CP4) |
///
/// Only the data length, list bit and data type are used by
/// [`SoeClient::read_value`] / [`SoeClient::write_value`]: the value is an integer of
/// `data_len` bytes, sign-extended when the data type is [`IdnDataType::Signed`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct IdnAttribute {
    /// The raw element.
    pub raw: u32,
    /// Conversion factor (bits 0–15).
    pub evaluation_factor: u16,
    /// Data length in bytes (1, 2, 4 or 8; of one item for lists).
    pub data_len: usize,
    /// List / variable-length data.
    pub list: bool,
    /// Procedure command.
    pub command: bool,
    /// Data type.
    pub data_type: IdnDataType,
    /// Decimal places.
    pub decimals: u8,
    /// Write protected in PRE-OP, SAFE-OP, OP.
    pub write_protected: [bool; 3],
}

impl IdnAttribute {
    /// Decode the attribute element (bit layout in the type documentation).
    pub fn decode(raw: u32) -> Self {
        let data_type = match (raw >> 20) & 7 {
            0 => IdnDataType::Binary,
            1 => IdnDataType::Unsigned,
            2 => IdnDataType::Signed,
            3 => IdnDataType::Hex,
            4 => IdnDataType::Text,
            5 => IdnDataType::Idn,
            6 => IdnDataType::Float,
            _ => IdnDataType::Parameter,
        };
        IdnAttribute {
            raw,
            evaluation_factor: raw as u16,
            data_len: 1 << ((raw >> 16) & 3),
            list: raw & (1 << 18) != 0,
            command: raw & (1 << 19) != 0,
            data_type,
            decimals: ((raw >> 24) & 0x0F) as u8,
            write_protected: [
                raw & (1 << 28) != 0,
                raw & (1 << 29) != 0,
                raw & (1 << 30) != 0,
            ],
        }
    }

    /// Values are sign-extended (data type signed integer).
    pub fn signed(&self) -> bool {
        self.data_type == IdnDataType::Signed
    }

    /// The value element is a single integer ([`SoeClient::read_value`] can decode it).
    pub fn is_integer(&self) -> bool {
        !self.list && !matches!(self.data_type, IdnDataType::Text | IdnDataType::Float)
    }
}

/// Little-endian integer of 1..=8 bytes, sign-extended when `signed`.
pub fn decode_value(bytes: &[u8], signed: bool) -> Result<i64, MailboxError> {
    let n = bytes.len();
    if n == 0 || n > 8 {
        return Err(MailboxError::Protocol(format!(
            "integer of {n} bytes (expected 1..=8)"
        )));
    }
    let mut w = [0u8; 8];
    w[..n].copy_from_slice(bytes);
    if signed && bytes[n - 1] & 0x80 != 0 {
        w[n..].fill(0xFF);
    }
    Ok(i64::from_le_bytes(w))
}

/// `value` as a little-endian integer of `len` (1, 2, 4 or 8) bytes;
/// [`MailboxError::ValueOutOfRange`] if it does not fit.
pub fn encode_value(value: i64, len: usize, signed: bool) -> Result<Vec<u8>, MailboxError> {
    let out_of_range = MailboxError::ValueOutOfRange { value, len, signed };
    if !matches!(len, 1 | 2 | 4 | 8) {
        return Err(out_of_range);
    }
    let bits = 8 * len as u32;
    let fits = match (signed, bits) {
        (true, 64) => true,
        (true, b) => {
            let lim = 1i64 << (b - 1);
            (-lim..lim).contains(&value)
        }
        (false, 64) => value >= 0,
        (false, b) => (0..(1i64 << b)).contains(&value),
    };
    if !fits {
        return Err(out_of_range);
    }
    Ok(value.to_le_bytes()[..len].to_vec())
}

/// Split write data into fragments of at most `cap` bytes: (fragment, fragments left after
/// it). One (empty) fragment for empty data. The SoE header of a fragment with fragments left
/// carries the incomplete bit and the count in its IDN field; the last one the IDN.
pub fn write_fragments(data: &[u8], cap: usize) -> Result<Vec<(&[u8], u16)>, MailboxError> {
    if cap == 0 {
        return Err(MailboxError::TooLarge(data.len()));
    }
    let chunks: Vec<&[u8]> = if data.is_empty() {
        vec![data]
    } else {
        data.chunks(cap).collect()
    };
    let n = chunks.len();
    if n - 1 > usize::from(u16::MAX) {
        return Err(MailboxError::TooLarge(data.len()));
    }
    Ok(chunks
        .into_iter()
        .enumerate()
        .map(|(k, c)| (c, (n - 1 - k) as u16))
        .collect())
}

/// SoE client for one SubDevice (see the module documentation), on a [`MailboxTransport`].
#[derive(Debug)]
pub struct SoeClient {
    transport: MailboxTransport,
    /// Bound for each wait (mailbox free, each reply or fragment).
    pub timeout: Duration,
    /// Bound of one whole read, request to last fragment (default
    /// [`super::mailbox::DEFAULT_TRANSFER_TIMEOUT`]; issue 28 item 1).
    pub transfer_timeout: Duration,
}

impl SoeClient {
    /// Client for the SubDevice at configured `station_address`, with the write mailbox
    /// (SM0) and read mailbox (SM1) as (start address, length).
    pub fn new(station_address: u16, mbx_out: (u16, u16), mbx_in: (u16, u16)) -> Self {
        Self::from_transport(MailboxTransport::new(station_address, mbx_out, mbx_in))
    }

    /// Client on an existing transport (e.g. shared with a [`super::mailbox::CoeClient`]);
    /// the timeout is the transport's.
    pub fn from_transport(transport: MailboxTransport) -> Self {
        Self {
            timeout: transport.timeout,
            transfer_timeout: super::mailbox::DEFAULT_TRANSFER_TIMEOUT,
            transport,
        }
    }

    /// The transport back (with this client's timeout).
    pub fn into_transport(mut self) -> MailboxTransport {
        self.transport.timeout = self.timeout;
        self.transport
    }

    /// CoE emergencies received so far (drains the list).
    pub fn take_emergencies(&mut self) -> Vec<Emergency> {
        self.transport.take_emergencies()
    }

    fn tp(&mut self) -> &mut MailboxTransport {
        self.transport.timeout = self.timeout;
        &mut self.transport
    }

    async fn send(
        &mut self,
        md: &MainDevice<'_>,
        h: SoeHeader,
        data: &[u8],
    ) -> Result<(), MailboxError> {
        let mut body = h.encode().to_vec();
        body.extend_from_slice(data);
        self.tp().send(md, MailboxType::Soe, &body).await
    }

    /// Next SoE reply of `opcode` for `drive_no` (notifications / slave info skipped); an
    /// error reply becomes [`MailboxError::Soe`].
    async fn receive(
        &mut self,
        md: &MainDevice<'_>,
        opcode: SoeOpcode,
        drive_no: u8,
        idn: u16,
        what: &'static str,
    ) -> Result<(SoeHeader, Vec<u8>), MailboxError> {
        loop {
            let body = self.tp().receive(md, MailboxType::Soe, what).await?;
            let (h, data) = SoeHeader::parse(&body)
                .map_err(|e| MailboxError::Protocol(format!("SoE header: {e}")))?;
            if matches!(h.opcode, SoeOpcode::Notification | SoeOpcode::Emergency) {
                tracing::debug!(?h, "SoE message skipped while waiting for {what}");
                continue;
            }
            if h.opcode != opcode {
                return Err(MailboxError::Protocol(format!(
                    "expected SoE {opcode:?}, got {:?}",
                    h.opcode
                )));
            }
            if h.drive_no != drive_no {
                return Err(MailboxError::Protocol(format!(
                    "SoE reply for drive {}, expected {drive_no}",
                    h.drive_no
                )));
            }
            if h.error {
                let code = data
                    .get(..2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]))
                    .ok_or_else(|| MailboxError::Protocol("SoE error reply without code".into()))?;
                return Err(MailboxError::Soe {
                    idn,
                    drive_no,
                    code,
                    text: error_text(code),
                });
            }
            return Ok((h, data.to_vec()));
        }
    }

    /// Read one element of `idn` (`drive_no` 0..7); fragmented replies are joined. Returns
    /// the element bytes as sent (a name keeps its SERCOS string lengths, see
    /// [`read_name`](Self::read_name)).
    pub async fn read_idn(
        &mut self,
        md: &MainDevice<'_>,
        drive_no: u8,
        idn: u16,
        element: Element,
    ) -> Result<Vec<u8>, MailboxError> {
        let flag = element.flag();
        let req = SoeHeader {
            opcode: SoeOpcode::ReadRequest,
            incomplete: false,
            error: false,
            drive_no,
            elements: flag,
            idn,
        };
        self.send(md, req, &[]).await?;
        let mut out = Vec::new();
        let mut left: Option<u16> = None;
        let start = std::time::Instant::now();
        let mut fragments = 0u64;
        loop {
            let after = start.elapsed();
            if after > self.transfer_timeout {
                return Err(MailboxError::TransferTimeout {
                    what: format!("SoE read of {} (drive {drive_no})", format_idn(idn)),
                    after,
                    progress: format!("{fragments} fragments, {} bytes", out.len()),
                });
            }
            fragments += 1;
            let (h, data) = self
                .receive(
                    md,
                    SoeOpcode::ReadResponse,
                    drive_no,
                    idn,
                    "SoE read response",
                )
                .await?;
            if h.elements != flag {
                return Err(MailboxError::Protocol(format!(
                    "SoE read response for elements {:#04x}, expected {flag:#04x}",
                    h.elements
                )));
            }
            if out.len() + data.len() > crate::limits::MAX_MAILBOX_OBJECT_BYTES {
                return Err(MailboxError::ObjectTooLarge {
                    size: out.len() + data.len(),
                    limit: crate::limits::MAX_MAILBOX_OBJECT_BYTES,
                });
            }
            out.extend_from_slice(&data);
            if h.incomplete {
                // IDN field = fragments left; must count down (bounds the loop).
                if left.is_some_and(|l| h.idn >= l) {
                    return Err(MailboxError::Protocol(format!(
                        "SoE fragments left {} after {left:?}",
                        h.idn
                    )));
                }
                left = Some(h.idn);
                continue;
            }
            if h.idn != idn {
                return Err(MailboxError::Protocol(format!(
                    "SoE read response for {}, expected {}",
                    format_idn(h.idn),
                    format_idn(idn)
                )));
            }
            return Ok(out);
        }
    }

    /// Write the value element of `idn`; data longer than the write mailbox are sent as
    /// fragments ([`write_fragments`]), the drive answers the last one.
    pub async fn write_idn(
        &mut self,
        md: &MainDevice<'_>,
        drive_no: u8,
        idn: u16,
        data: &[u8],
    ) -> Result<(), MailboxError> {
        let flag = Element::Value.flag();
        let cap = self.transport.max_body_len().saturating_sub(SoeHeader::LEN);
        for (chunk, left) in write_fragments(data, cap)? {
            let h = SoeHeader {
                opcode: SoeOpcode::WriteRequest,
                incomplete: left > 0,
                error: false,
                drive_no,
                elements: flag,
                idn: if left > 0 { left } else { idn },
            };
            self.send(md, h, chunk).await?;
        }
        let (h, _) = self
            .receive(
                md,
                SoeOpcode::WriteResponse,
                drive_no,
                idn,
                "SoE write response",
            )
            .await?;
        if h.idn != idn {
            return Err(MailboxError::Protocol(format!(
                "SoE write response for {}, expected {}",
                format_idn(h.idn),
                format_idn(idn)
            )));
        }
        Ok(())
    }

    /// Name element as text (SERCOS string: current length u16, maximum length u16,
    /// characters; invalid UTF-8 replaced).
    pub async fn read_name(
        &mut self,
        md: &MainDevice<'_>,
        drive_no: u8,
        idn: u16,
    ) -> Result<String, MailboxError> {
        let b = self.read_idn(md, drive_no, idn, Element::Name).await?;
        if b.len() < 4 {
            return Err(MailboxError::Protocol(format!(
                "SoE name of {} bytes",
                b.len()
            )));
        }
        let cur = usize::from(u16::from_le_bytes([b[0], b[1]]));
        let text = b.get(4..4 + cur).ok_or_else(|| {
            MailboxError::Protocol(format!(
                "SoE name length {cur} beyond the {} bytes received",
                b.len() - 4
            ))
        })?;
        Ok(String::from_utf8_lossy(text).into_owned())
    }

    /// Attribute element, decoded.
    pub async fn read_attribute(
        &mut self,
        md: &MainDevice<'_>,
        drive_no: u8,
        idn: u16,
    ) -> Result<IdnAttribute, MailboxError> {
        let b = self.read_idn(md, drive_no, idn, Element::Attribute).await?;
        let raw: [u8; 4] = b
            .as_slice()
            .try_into()
            .map_err(|_| MailboxError::Protocol(format!("SoE attribute of {} bytes", b.len())))?;
        Ok(IdnAttribute::decode(u32::from_le_bytes(raw)))
    }

    fn integer_attribute(idn: u16, a: &IdnAttribute) -> Result<(), MailboxError> {
        if a.is_integer() {
            Ok(())
        } else {
            Err(MailboxError::Protocol(format!(
                "{} is not a single integer (attribute {:#010x}: {:?}{})",
                format_idn(idn),
                a.raw,
                a.data_type,
                if a.list { ", list" } else { "" }
            )))
        }
    }

    /// Value of an integer IDN: reads the attribute for the data length (1/2/4/8 bytes) and
    /// signedness ([`IdnAttribute`]), then the value element.
    pub async fn read_value(
        &mut self,
        md: &MainDevice<'_>,
        drive_no: u8,
        idn: u16,
    ) -> Result<i64, MailboxError> {
        let a = self.read_attribute(md, drive_no, idn).await?;
        Self::integer_attribute(idn, &a)?;
        let b = self.read_idn(md, drive_no, idn, Element::Value).await?;
        if b.len() != a.data_len {
            return Err(MailboxError::Protocol(format!(
                "{}: value of {} bytes, attribute says {}",
                format_idn(idn),
                b.len(),
                a.data_len
            )));
        }
        decode_value(&b, a.signed())
    }

    /// Write an integer IDN: reads the attribute for the data length and signedness, checks
    /// that `value` fits ([`MailboxError::ValueOutOfRange`] otherwise, nothing written), then
    /// writes the value element.
    pub async fn write_value(
        &mut self,
        md: &MainDevice<'_>,
        drive_no: u8,
        idn: u16,
        value: i64,
    ) -> Result<(), MailboxError> {
        let a = self.read_attribute(md, drive_no, idn).await?;
        Self::integer_attribute(idn, &a)?;
        let b = encode_value(value, a.data_len, a.signed())?;
        self.write_idn(md, drive_no, idn, &b).await
    }
}

#[cfg(all(test, feature = "sim"))]
mod tests {
    use super::*;
    use crate::sim::esc::soe::{error, sercos_idns};

    #[test]
    fn idn_names() {
        assert_eq!(parse_idn("S-0-0092"), Some(0x005C));
        assert_eq!(parse_idn("P-0-0010"), Some(0x800A));
        assert_eq!(parse_idn("S-1-0092"), Some(0x105C));
        assert_eq!(parse_idn("S-8-0092"), None);
        assert_eq!(format_idn(0x00A9), "S-0-0169");
        for code in [0u16, 92, 0x105C, 0x800A, 0xFFFF] {
            assert_eq!(parse_idn(&format_idn(code)), Some(code));
        }
    }

    #[test]
    fn server_error_codes_have_words() {
        for c in [
            error::NO_IDN,
            error::INVALID_ELEMENT,
            error::NO_NAME,
            error::DATA_TOO_SHORT,
            error::DATA_TOO_LONG,
            error::READ_ONLY,
            error::INVALID_DATA,
        ] {
            assert_ne!(error_text(c), "unknown SoE error code", "{c:#06x}");
        }
        assert_eq!(error_text(0x1001), "IDN does not exist");
        assert_eq!(error_text(0x7004), "data cannot be changed (read only)");
    }

    #[test]
    fn attribute_matches_the_emulator_table() {
        for e in sercos_idns() {
            let a = IdnAttribute::decode(e.attribute());
            assert_eq!(a.data_len, usize::from(e.len), "{}", e.name);
            assert_eq!(a.signed(), e.signed, "{}", e.name);
            assert_eq!(a.write_protected, [!e.writable; 3], "{}", e.name);
            assert!(a.is_integer());
            assert_eq!(a.evaluation_factor, 1);
        }
        let a = IdnAttribute::decode(0x0045_0000 | 3 << 16);
        assert_eq!(
            (a.data_len, a.list, a.data_type),
            (8, true, IdnDataType::Text)
        );
        assert!(!a.is_integer());
    }

    #[test]
    fn value_codec() {
        assert_eq!(decode_value(&[0xFF, 0xFF], true).unwrap(), -1);
        assert_eq!(decode_value(&[0xFF, 0xFF], false).unwrap(), 0xFFFF);
        assert_eq!(
            decode_value(&[0, 0, 0, 0x80], true).unwrap(),
            i64::from(i32::MIN)
        );
        assert!(decode_value(&[], false).is_err());
        assert!(decode_value(&[0; 9], false).is_err());
        assert_eq!(encode_value(500, 2, false).unwrap(), vec![0xF4, 0x01]);
        assert_eq!(encode_value(-1, 4, true).unwrap(), vec![0xFF; 4]);
        assert_eq!(
            encode_value(i64::MIN, 8, true).unwrap(),
            i64::MIN.to_le_bytes()
        );
        assert!(encode_value(-1, 2, false).is_err());
        assert!(encode_value(0x1_0000, 2, false).is_err());
        assert!(encode_value(128, 1, true).is_err());
        assert!(encode_value(-129, 1, true).is_err());
        assert!(encode_value(1, 3, false).is_err());
        for (v, len, signed) in [(-5i64, 1, true), (200, 1, false), (-70_000, 4, true)] {
            let b = encode_value(v, len, signed).unwrap();
            assert_eq!(decode_value(&b, signed).unwrap(), v);
        }
    }

    #[test]
    fn fragments_cover_every_split() {
        let data: Vec<u8> = (0..23).collect();
        for cap in 1..30 {
            let f = write_fragments(&data, cap).unwrap();
            let joined: Vec<u8> = f.iter().flat_map(|(c, _)| c.iter().copied()).collect();
            assert_eq!(joined, data, "cap {cap}");
            assert!(f.iter().all(|(c, _)| c.len() <= cap));
            let lefts: Vec<u16> = f.iter().map(|(_, l)| *l).collect();
            let want: Vec<u16> = (0..f.len() as u16).rev().collect();
            assert_eq!(lefts, want, "cap {cap}");
        }
        assert_eq!(write_fragments(&[], 4).unwrap(), vec![(&[][..], 0)]);
        assert!(write_fragments(&data, 0).is_err());
    }
}
