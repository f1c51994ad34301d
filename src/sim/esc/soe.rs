//! SoE (Servo drive profile over EtherCAT, mailbox type 5) server for an emulated ESC
//! application. Spec source: ETG.1000.6 SoE (the layout of SOEM's `ec_soe.c`).
//!
//! [`SoeServer`] answers IDN read requests (opcode 1 → 2) and write requests (opcode 3 → 4)
//! for the IDNs of an [`IdnEntry`] table; values go through the [`DriveModel`]
//! (`read_object(idn, 0)` / `write_object(idn, 0, v)`, as
//! [`crate::drive::model::sercos::SercosModel`] implements them). Elements: value (0x40), name
//! (0x02, SERCOS string: current length u16, maximum length u16, characters) and attribute
//! (0x04, u32); several flags in one request are answered in ascending flag order. Unknown IDNs
//! and unsupported elements are answered with the error bit and a 2-byte SERCOS error code
//! ([`error`]). Read responses longer than the mailbox are fragmented (incomplete flag, the IDN
//! field holding the fragments left; the fragments after the first wait in the outgoing
//! queue, see [`SoeServer::take_outgoing`]); fragmented write requests are collected until the
//! last fragment, at most [`SOE_WRITE_MAX`] bytes.

use std::collections::VecDeque;

use crate::bus::ethercat::wire::{MailboxHeader, MailboxType, SoeHeader, SoeOpcode};
use crate::drive::model::{abort, DriveModel};

use super::app::EscApplication;
use super::coe::{mailbox_error, mailbox_error_message, mailbox_message, MailboxCounter};

/// SERCOS error codes of SoE error responses (IEC 61800-7-204 / SOEM; from memory).
pub mod error {
    /// 0x1001 — IDN not available.
    pub const NO_IDN: u16 = 0x1001;
    /// 0x1009 — invalid access to element 1 (element not supported).
    pub const INVALID_ELEMENT: u16 = 0x1009;
    /// 0x2001 — name not available.
    pub const NO_NAME: u16 = 0x2001;
    /// 0x7002 — data transmitted too short.
    pub const DATA_TOO_SHORT: u16 = 0x7002;
    /// 0x7003 — data transmitted too long.
    pub const DATA_TOO_LONG: u16 = 0x7003;
    /// 0x7004 — data cannot be changed (read only).
    pub const READ_ONLY: u16 = 0x7004;
    /// 0x7008 — invalid data.
    pub const INVALID_DATA: u16 = 0x7008;
}

/// Longest write data collected from fragments (bytes): a SERCOS list element is at most
/// 4 + 65,532 bytes (current and maximum length u16, then the data; IEC 61800-7-204), and no
/// IDN of the emulated drives is longer than 8 bytes. A fragmented write that would exceed it
/// is answered with the error 0x7003 "data transmitted too long" and dropped.
pub const SOE_WRITE_MAX: usize = 65_536;

/// Element flag: value.
pub const ELEM_VALUE: u8 = 0x40;
/// Element flag: name.
pub const ELEM_NAME: u8 = 0x02;
/// Element flag: attribute.
pub const ELEM_ATTRIBUTE: u8 = 0x04;

/// One IDN the server knows.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdnEntry {
    /// IDN (bit 15 P, bits 12–14 parameter set, bits 0–11 number).
    pub idn: u16,
    /// Name element.
    pub name: String,
    /// Value length in bytes (1, 2, 4 or 8).
    pub len: u8,
    /// Signed value (attribute data type 2, else 1 = unsigned).
    pub signed: bool,
    /// Writable.
    pub writable: bool,
}

impl IdnEntry {
    /// Entry with these properties.
    pub fn new(idn: u16, name: &str, len: u8, signed: bool, writable: bool) -> Self {
        Self {
            idn,
            name: name.to_string(),
            len,
            signed,
            writable,
        }
    }

    /// Attribute element: evaluation factor 1, length code (bits 16–17), data type
    /// (bits 20–22: 1 unsigned, 2 signed), write protection in PRE-OP/SAFE-OP/OP (bits 28–30)
    /// for read-only IDNs.
    pub fn attribute(&self) -> u32 {
        let len_code = match self.len {
            1 => 0,
            2 => 1,
            4 => 2,
            _ => 3,
        };
        let ty = if self.signed { 2 } else { 1 };
        let wp = if self.writable { 0 } else { 0b111 << 28 };
        1 | (len_code << 16) | (ty << 20) | wp
    }
}

/// IDN table for [`crate::drive::model::sercos::SercosModel`].
pub fn sercos_idns() -> Vec<IdnEntry> {
    let e = IdnEntry::new;
    vec![
        e(11, "Class 1 diagnostic", 2, false, false),
        e(47, "Position command value", 4, true, true),
        e(51, "Position feedback value 1", 4, true, false),
        e(84, "Torque feedback value", 2, true, false),
        e(92, "Bipolar torque limit value", 2, false, true),
        e(99, "Reset class 1 diagnostic", 2, false, true),
        e(130, "Probe value 1 positive edge", 4, true, false),
        e(131, "Probe value 1 negative edge", 4, true, false),
        e(132, "Probe value 2 positive edge", 4, true, false),
        e(133, "Probe value 2 negative edge", 4, true, false),
        e(134, "Master control word", 2, false, true),
        e(135, "Drive status word", 2, false, false),
        e(159, "Monitoring window", 4, false, true),
        e(169, "Probe control parameter", 2, false, true),
        e(170, "Probing cycle procedure command", 2, false, true),
        e(179, "Probe status", 2, false, false),
        e(189, "Following distance", 4, true, false),
        e(301, "Allocation of real-time control bit 1", 2, false, true),
        e(303, "Allocation of real-time control bit 2", 2, false, true),
        e(305, "Allocation of real-time status bit 1", 2, false, true),
        e(307, "Allocation of real-time status bit 2", 2, false, true),
        e(401, "Probe 1", 2, false, false),
        e(402, "Probe 2", 2, false, false),
        e(405, "Probe 1 enable", 2, false, false),
        e(406, "Probe 2 enable", 2, false, false),
        e(409, "Probe 1 positive latched", 2, false, false),
        e(410, "Probe 1 negative latched", 2, false, false),
        e(411, "Probe 2 positive latched", 2, false, false),
        e(412, "Probe 2 negative latched", 2, false, false),
    ]
}

#[derive(Debug, Clone)]
struct WriteFragments {
    idn: u16,
    elements: u8,
    drive_no: u8,
    data: Vec<u8>,
}

/// SoE server over a drive model and an IDN table.
#[derive(Debug)]
pub struct SoeServer {
    model: Box<dyn DriveModel>,
    idns: Vec<IdnEntry>,
    mbx_size: usize,
    counter: MailboxCounter,
    last_request_counter: u8,
    outgoing: VecDeque<Vec<u8>>,
    write: Option<WriteFragments>,
}

impl SoeServer {
    /// Server over `model` with the IDNs `idns`; `mailbox_size` is the read mailbox (SM1) size.
    pub fn new(model: Box<dyn DriveModel>, idns: Vec<IdnEntry>, mailbox_size: usize) -> Self {
        Self {
            model,
            idns,
            mbx_size: mailbox_size.max(MailboxHeader::LEN + SoeHeader::LEN + 2),
            counter: MailboxCounter::default(),
            last_request_counter: 0,
            outgoing: VecDeque::new(),
            write: None,
        }
    }

    /// The drive model.
    pub fn model(&self) -> &dyn DriveModel {
        self.model.as_ref()
    }

    /// The drive model, mutable.
    pub fn model_mut(&mut self) -> &mut dyn DriveModel {
        self.model.as_mut()
    }

    /// End of a mailbox session (the device entered INIT): the request repeat counter and the
    /// device's own counter start again (ETG.1000.4 §5.6, a new master starts at counter 1), a
    /// fragmented write in progress and queued read fragments are dropped.
    pub fn reset_session(&mut self) {
        self.counter = MailboxCounter::default();
        self.last_request_counter = 0;
        self.outgoing.clear();
        self.write = None;
    }

    /// Bytes of a fragmented write collected so far (at most [`SOE_WRITE_MAX`]).
    pub fn write_fragments_len(&self) -> usize {
        self.write.as_ref().map_or(0, |w| w.data.len())
    }

    /// Add or replace an IDN entry.
    pub fn insert(&mut self, e: IdnEntry) {
        self.idns.retain(|x| x.idn != e.idn);
        self.idns.push(e);
    }

    /// Messages waiting for the read mailbox (further fragments), oldest first.
    pub fn take_outgoing(&mut self) -> Vec<Vec<u8>> {
        self.outgoing.drain(..).collect()
    }

    fn message(&mut self, hdr: SoeHeader, data: &[u8]) -> Vec<u8> {
        let mut body = hdr.encode().to_vec();
        body.extend_from_slice(data);
        let c = self.counter.advance();
        mailbox_message(MailboxType::Soe, c, &body)
    }

    fn error_reply(
        &mut self,
        op: SoeOpcode,
        drive_no: u8,
        elements: u8,
        idn: u16,
        code: u16,
    ) -> Vec<u8> {
        let h = SoeHeader {
            opcode: op,
            incomplete: false,
            error: true,
            drive_no,
            elements,
            idn,
        };
        self.message(h, &code.to_le_bytes())
    }

    fn read_elements(&self, e: &IdnEntry, elements: u8) -> Result<Vec<u8>, u16> {
        if elements == 0 || elements & !(ELEM_VALUE | ELEM_NAME | ELEM_ATTRIBUTE) != 0 {
            return Err(error::INVALID_ELEMENT);
        }
        let mut out = Vec::new();
        if elements & ELEM_NAME != 0 {
            let n = e.name.len() as u16;
            out.extend_from_slice(&n.to_le_bytes());
            out.extend_from_slice(&n.to_le_bytes());
            out.extend_from_slice(e.name.as_bytes());
        }
        if elements & ELEM_ATTRIBUTE != 0 {
            out.extend_from_slice(&e.attribute().to_le_bytes());
        }
        if elements & ELEM_VALUE != 0 {
            let v = self.model.read_object(e.idn, 0).map_err(map_abort)?;
            out.extend_from_slice(&v.to_le_bytes()[..usize::from(e.len.min(8))]);
        }
        Ok(out)
    }

    fn write_value(&mut self, idn: u16, elements: u8, data: &[u8]) -> Result<(), u16> {
        let e = self
            .idns
            .iter()
            .find(|e| e.idn == idn)
            .cloned()
            .ok_or(error::NO_IDN)?;
        if elements != ELEM_VALUE {
            return Err(error::INVALID_ELEMENT);
        }
        if !e.writable {
            return Err(error::READ_ONLY);
        }
        let n = usize::from(e.len.min(8));
        if data.len() < n {
            return Err(error::DATA_TOO_SHORT);
        }
        if data.len() > n {
            return Err(error::DATA_TOO_LONG);
        }
        let mut w = [0u8; 8];
        w[..n].copy_from_slice(data);
        if e.signed && data[n - 1] & 0x80 != 0 {
            w[n..].fill(0xFF);
        }
        self.model
            .write_object(idn, 0, i64::from_le_bytes(w))
            .map_err(map_abort)
    }

    /// Handle one mailbox message from the write mailbox; returns the reply due now.
    pub fn handle(&mut self, msg: &[u8]) -> Option<Vec<u8>> {
        let Ok((mh, body)) = MailboxHeader::parse(msg) else {
            let c = self.counter.advance();
            return Some(mailbox_error_message(c, mailbox_error::SYNTAX));
        };
        if mh.counter != 0 && mh.counter == self.last_request_counter {
            return None;
        }
        self.last_request_counter = mh.counter;
        if mh.mailbox_type != MailboxType::Soe {
            let c = self.counter.advance();
            return Some(mailbox_error_message(
                c,
                mailbox_error::UNSUPPORTED_PROTOCOL,
            ));
        }
        let Ok((h, data)) = SoeHeader::parse(body) else {
            let c = self.counter.advance();
            return Some(mailbox_error_message(c, mailbox_error::INVALID_HEADER));
        };
        match h.opcode {
            SoeOpcode::ReadRequest => {
                let r = self
                    .idns
                    .iter()
                    .find(|e| e.idn == h.idn)
                    .ok_or(error::NO_IDN)
                    .and_then(|e| self.read_elements(e, h.elements));
                match r {
                    Ok(d) => Some(self.read_response(h, &d)),
                    Err(code) => Some(self.error_reply(
                        SoeOpcode::ReadResponse,
                        h.drive_no,
                        h.elements,
                        h.idn,
                        code,
                    )),
                }
            }
            SoeOpcode::WriteRequest => {
                let mut frag = match self.write.take() {
                    Some(f) => f,
                    None => WriteFragments {
                        idn: h.idn,
                        elements: h.elements,
                        drive_no: h.drive_no,
                        data: Vec::new(),
                    },
                };
                if frag.data.len() + data.len() > SOE_WRITE_MAX {
                    // Beyond the longest SERCOS element: the transfer is refused and forgotten;
                    // further fragments of it start a new one (and are refused the same way).
                    return Some(self.error_reply(
                        SoeOpcode::WriteResponse,
                        frag.drive_no,
                        frag.elements,
                        frag.idn,
                        error::DATA_TOO_LONG,
                    ));
                }
                frag.data.extend_from_slice(data);
                if h.incomplete {
                    // IDN field = fragments left; no answer until the last fragment.
                    self.write = Some(frag);
                    return None;
                }
                // Only the last fragment carries the IDN (the others: fragments left).
                frag.idn = h.idn;
                let r = self.write_value(frag.idn, frag.elements, &frag.data);
                let reply = match r {
                    Ok(()) => {
                        let rh = SoeHeader {
                            opcode: SoeOpcode::WriteResponse,
                            incomplete: false,
                            error: false,
                            drive_no: frag.drive_no,
                            elements: frag.elements,
                            idn: frag.idn,
                        };
                        self.message(rh, &[])
                    }
                    Err(code) => self.error_reply(
                        SoeOpcode::WriteResponse,
                        frag.drive_no,
                        frag.elements,
                        frag.idn,
                        code,
                    ),
                };
                Some(reply)
            }
            _ => {
                let c = self.counter.advance();
                Some(mailbox_error_message(
                    c,
                    mailbox_error::SERVICE_NOT_SUPPORTED,
                ))
            }
        }
    }

    fn read_response(&mut self, h: SoeHeader, d: &[u8]) -> Vec<u8> {
        let max = self.mbx_size - MailboxHeader::LEN - SoeHeader::LEN;
        let chunks: Vec<&[u8]> = if d.is_empty() {
            vec![d]
        } else {
            d.chunks(max).collect()
        };
        let n = chunks.len();
        let mut first = None;
        for (k, c) in chunks.into_iter().enumerate() {
            let left = n - 1 - k;
            let rh = SoeHeader {
                opcode: SoeOpcode::ReadResponse,
                incomplete: left > 0,
                error: false,
                drive_no: h.drive_no,
                elements: h.elements,
                idn: if left > 0 { left as u16 } else { h.idn },
            };
            let m = self.message(rh, c);
            if first.is_none() {
                first = Some(m);
            } else {
                self.outgoing.push_back(m);
            }
        }
        first.unwrap_or_default()
    }
}

/// SERCOS error code for a model's CiA 301 abort code.
pub fn map_abort(code: u32) -> u16 {
    match code {
        abort::NO_OBJECT => error::NO_IDN,
        abort::READ_ONLY => error::READ_ONLY,
        abort::VALUE_RANGE => error::INVALID_DATA,
        abort::NO_SUB_INDEX => error::INVALID_ELEMENT,
        _ => error::INVALID_DATA,
    }
}

impl EscApplication for SoeServer {
    fn mailbox_received(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        self.handle(data)
    }

    fn mailbox_reset(&mut self) {
        self.reset_session();
    }
}
