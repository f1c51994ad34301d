//! CoE (CANopen over EtherCAT) mailbox server for an emulated ESC application.
//!
//! [`CoeServer`] answers SDO requests (CoE service 2) from an object dictionary given as a
//! table of [`ObjectEntry`]s. Numeric entries are read and written through a [`DriveModel`]
//! (`read_object(index, sub)` / `write_object`); byte-string entries (device name, large test
//! objects) are stored in the entry itself. Spec sources: ETG.1000.4 (mailbox), ETG.1000.6 §5.6 and CiA 301 §7.2.4 (SDO protocol).
//!
//! Implemented:
//! * SDO upload expedited (≤ 4 bytes, always expedited — ethercrab requires it), normal (the
//!   data fits the read mailbox) and segmented (initiate response with the size only, then
//!   upload segments with alternating toggle bit, `scs = 0`, the last-segment flag and the
//!   unused-byte count for segments shorter than 7 bytes);
//! * SDO download expedited, normal and segmented (data in the initiate request may be followed
//!   by download segments; toggle checked, total size checked);
//! * complete access (CA bit), upload and download, for every record/array of a device whose
//!   ESI declares it (`Mailbox/CoE@CompleteAccess`, SII CoE details bit 5; a device that does
//!   not declare it answers every CA request with abort 0x06010000 "unsupported access to an
//!   object", [`CoeServer::set_complete_access`]), starting at sub 0 (sub 0 padded to 16 bits,
//!   ETG.1000.6 §5.6.2.1.2 complete access; SOEM's `ec_PDOassignt` reads it so) or sub 1
//!   (ethercrab's `SubIndex::Complete`); downloads to PDO objects follow the PDO rules
//!   ([`super::pdo_rules`]);
//! * SDO abort requests (CoE service 2, command 0x80) with CiA 301 abort codes ([`abort`]);
//! * emergency messages (CoE service 1) queued by [`CoeServer::emergency`] or when the model's
//!   error code changes ([`CoeServer::poll`]);
//! * mailbox counter: replies count 1..7 (wrapping 7 → 1); a request repeating the previous
//!   non-zero counter is a retry and is ignored (ETG.1000.4 mailbox repeat rule); both counters
//!   start again when the device enters INIT ([`CoeServer::reset_session`]), where a new master
//!   starts at counter 1;
//! * mailbox error replies (type 0) for other mailbox types and malformed headers;
//! * fault knobs ([`CoeFaults`]): hold the answer back for N [`CoeServer::poll`] calls, and
//!   answer the next SDO request with an EMCY first (the SDO response follows in the queue).
//!
//! * SDO information (service 8, ETG.1000.6 §5.6.3): Get OD List, Get Object Description, Get
//!   Entry Description, answered from the server's [`OdDescriptions`] (from the ESI dictionary
//!   for an emulated device, [`super::device`]; else from the table itself), fragmented to the
//!   read mailbox; the fragments after the first wait in the outgoing queue
//!   ([`CoeServer::take_outgoing`]) and go out one per mailbox read.
//!
//! Not implemented: PDO services over the mailbox, block transfers. An abort request from the
//! master cancels a running transfer and gets no answer.
//!
//! Device-initiated messages (EMCY, delayed replies) are collected in an outgoing queue; the
//! owner of the [`super::Esc`] moves them with [`CoeServer::poll`] / [`CoeServer::take_outgoing`]
//! into [`super::Esc::push_mailbox`].

use std::collections::VecDeque;

use crate::bus::ethercat::wire::{
    CoeHeader, CoeService, MailboxHeader, MailboxType, SdoCommand, SdoDirection, SdoFrame,
};
use crate::drive::model::DriveModel;

use super::app::EscApplication;
use super::sdo_info::OdDescriptions;

/// CiA 301 SDO abort codes used by the server (the model's codes are in
/// [`crate::drive::model::abort`]).
pub mod abort {
    pub use crate::drive::model::abort::{NO_OBJECT, NO_SUB_INDEX, READ_ONLY, VALUE_RANGE};
    /// 0x05030000 — toggle bit not alternated.
    pub const TOGGLE: u32 = 0x0503_0000;
    /// 0x05040001 — client/server command specifier not valid or unknown.
    pub const UNKNOWN_COMMAND: u32 = 0x0504_0001;
    /// 0x06010001 — attempt to read a write-only object.
    pub const WRITE_ONLY: u32 = 0x0601_0001;
    /// 0x06010000 — unsupported access to an object.
    pub const UNSUPPORTED_ACCESS: u32 = 0x0601_0000;
    /// 0x06070010 — data type does not match, length of service parameter does not match.
    pub const LENGTH: u32 = 0x0607_0010;
    /// 0x05040005 — out of memory (a download larger than the server takes).
    pub const OUT_OF_MEMORY: u32 = 0x0504_0005;
    /// 0x08000000 — general error.
    pub const GENERAL: u32 = 0x0800_0000;
}

/// Largest SDO download (bytes) the server collects: larger than every object of the emulated
/// dictionaries (the longest is a few hundred bytes); an initiate request announcing more is
/// aborted with 0x05040005 "out of memory" (CiA 301 §7.2.4.3.17), so segments from the wire
/// never grow the server beyond this.
pub const SDO_DOWNLOAD_MAX: usize = 65_536;

/// Mailbox error detail codes (ETG.1000.4 mailbox error reply, type 0, service 1).
pub mod mailbox_error {
    /// Syntax of the 6-byte mailbox header is wrong.
    pub const SYNTAX: u16 = 0x0001;
    /// The mailbox protocol is not supported.
    pub const UNSUPPORTED_PROTOCOL: u16 = 0x0002;
    /// The service in the mailbox protocol is not supported.
    pub const SERVICE_NOT_SUPPORTED: u16 = 0x0004;
    /// The mailbox protocol header is wrong (without the 6-byte header).
    pub const INVALID_HEADER: u16 = 0x0005;
    /// Length of the received mailbox data is too short.
    pub const SIZE_TOO_SHORT: u16 = 0x0006;
}

/// Data type of an object dictionary entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    /// BOOLEAN (1 byte on the wire).
    Bool,
    /// INTEGER8.
    I8,
    /// UNSIGNED8.
    U8,
    /// INTEGER16.
    I16,
    /// UNSIGNED16.
    U16,
    /// INTEGER32.
    I32,
    /// UNSIGNED32.
    U32,
    /// INTEGER64.
    I64,
    /// UNSIGNED64.
    U64,
    /// VISIBLE_STRING / OCTET_STRING with this maximum length (stored in the entry).
    Bytes(usize),
}

impl DataType {
    /// Fixed size in bytes (`None` for byte strings).
    pub fn size(self) -> Option<usize> {
        Some(match self {
            DataType::Bool | DataType::I8 | DataType::U8 => 1,
            DataType::I16 | DataType::U16 => 2,
            DataType::I32 | DataType::U32 => 4,
            DataType::I64 | DataType::U64 => 8,
            DataType::Bytes(_) => return None,
        })
    }

    fn signed(self) -> bool {
        matches!(
            self,
            DataType::I8 | DataType::I16 | DataType::I32 | DataType::I64
        )
    }

    /// Little-endian encoding of `v` in this type (truncating).
    pub fn encode(self, v: i64) -> Vec<u8> {
        let n = self.size().unwrap_or(8);
        v.to_le_bytes()[..n].to_vec()
    }

    /// Decode little-endian bytes of exactly this type's size (sign-extended for signed types).
    pub fn decode(self, b: &[u8]) -> Option<i64> {
        let n = self.size()?;
        if b.len() != n {
            return None;
        }
        let mut w = [0u8; 8];
        w[..n].copy_from_slice(b);
        if self.signed() && b[n - 1] & 0x80 != 0 {
            w[n..].fill(0xFF);
        }
        Some(i64::from_le_bytes(w))
    }
}

/// Access rights of an entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Read only.
    Ro,
    /// Read and write.
    Rw,
    /// Write only.
    Wo,
}

/// One object dictionary entry (index, sub-index).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectEntry {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Data type.
    pub ty: DataType,
    /// Access.
    pub access: Access,
    /// Value of a [`DataType::Bytes`] entry, or a constant for a numeric entry (then the model
    /// is not asked). `None` for numeric entries backed by the model.
    pub data: Option<Vec<u8>>,
}

impl ObjectEntry {
    /// Numeric entry backed by the drive model.
    pub fn model(index: u16, sub: u8, ty: DataType, access: Access) -> Self {
        Self {
            index,
            sub,
            ty,
            access,
            data: None,
        }
    }

    /// Read-only numeric constant (e.g. sub 0 "number of entries" of a record).
    pub fn constant(index: u16, sub: u8, ty: DataType, value: i64) -> Self {
        Self {
            index,
            sub,
            ty,
            access: Access::Ro,
            data: Some(ty.encode(value)),
        }
    }

    /// Byte-string entry (VISIBLE_STRING / OCTET_STRING) with this initial content; the maximum
    /// length is `max(len, content length)`.
    pub fn bytes(index: u16, sub: u8, access: Access, content: &[u8], max_len: usize) -> Self {
        Self {
            index,
            sub,
            ty: DataType::Bytes(max_len.max(content.len())),
            access,
            data: Some(content.to_vec()),
        }
    }
}

/// Content of object 0x2000:00 "emulator notice" (VISIBLE_STRING, read-only) of
/// [`ds402_objects`]. It is longer than a 128-byte mailbox can carry in one upload response
/// (128 − 16 = 112 bytes), so a master has to read it with a segmented upload (CiA 301 §7.2.4.3.4,
/// ETG.1000.6 §5.6.2.3); the interop test with SOEM checks it byte for byte.
pub const EMULATOR_NOTICE: &str = "fieldprobe emulated CiA 402 servo drive. Not a vendor \
device: SII, object dictionary and process data are generated from the ESI file and the drive \
definition; the drive model runs one step per process-data exchange.";

/// The object table for a CiA 402 drive model: 0x1000 device type, 0x1008 device name, the
/// CiA 402 objects [`crate::drive::model::ds402::Ds402Model`] implements, 0x60D0 as an array,
/// 0x1C00 sync manager communication types, and 0x2000 [`EMULATOR_NOTICE`] (a read-only string
/// long enough for a segmented upload).
///
/// 0x1C00 (ETG.1000.6 §5.6.7.4.1, UINT8 array) describes the standard layout of a device with a
/// mailbox: SM0 mailbox out (1), SM1 mailbox in (2), SM2 outputs (3), SM3 inputs (4). SOEM reads
/// it before 0x1C12/0x1C13 (`ecx_readPDOmap`) and fails the mapping without it; ethercrab 0.7.1
/// does not read it.
pub fn ds402_objects(device_name: &str) -> Vec<ObjectEntry> {
    use Access::*;
    use DataType::*;
    let m = ObjectEntry::model;
    vec![
        ObjectEntry::constant(0x1000, 0, U32, 0x0002_0192),
        ObjectEntry::bytes(0x1008, 0, Ro, device_name.as_bytes(), 0),
        ObjectEntry::constant(0x1C00, 0, U8, 4),
        ObjectEntry::constant(0x1C00, 1, U8, 1),
        ObjectEntry::constant(0x1C00, 2, U8, 2),
        ObjectEntry::constant(0x1C00, 3, U8, 3),
        ObjectEntry::constant(0x1C00, 4, U8, 4),
        ObjectEntry::bytes(0x2000, 0, Ro, EMULATOR_NOTICE.as_bytes(), 0),
        m(0x603F, 0, U16, Ro),
        m(0x6040, 0, U16, Rw),
        m(0x6041, 0, U16, Ro),
        m(0x6060, 0, I8, Rw),
        m(0x6061, 0, I8, Ro),
        m(0x6064, 0, I32, Ro),
        m(0x6065, 0, U32, Rw),
        m(0x6066, 0, U16, Rw),
        m(0x6067, 0, U32, Rw),
        m(0x606C, 0, I32, Ro),
        m(0x6072, 0, U16, Rw),
        m(0x6077, 0, I16, Ro),
        m(0x607A, 0, I32, Rw),
        m(0x60B8, 0, U16, Rw),
        m(0x60B9, 0, U16, Ro),
        m(0x60BA, 0, I32, Ro),
        m(0x60BB, 0, I32, Ro),
        m(0x60BC, 0, I32, Ro),
        m(0x60BD, 0, I32, Ro),
        m(0x60D0, 0, U8, Ro),
        m(0x60D0, 1, I16, Rw),
        m(0x60D0, 2, I16, Rw),
        m(0x60E0, 0, U16, Rw),
        m(0x60E1, 0, U16, Rw),
        m(0x60F4, 0, I32, Ro),
        m(0x6502, 0, U32, Ro),
    ]
}

/// Fault knobs of the server.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CoeFaults {
    /// Hold every SDO answer back for this many [`CoeServer::poll`] calls (0 = answer in the
    /// mailbox cycle of the request).
    pub delay_polls: u32,
    /// Before the answer to the next SDO request, send this EMCY (error code, error register);
    /// the SDO answer follows in the outgoing queue. Cleared when used.
    pub emcy_before_next_sdo: Option<(u16, u8)>,
}

#[derive(Debug, Clone)]
struct Upload {
    index: u16,
    sub: u8,
    data: Vec<u8>,
    pos: usize,
    toggle: bool,
}

#[derive(Debug, Clone)]
struct Download {
    index: u16,
    sub: u8,
    complete_access: bool,
    size: usize,
    data: Vec<u8>,
    toggle: bool,
}

/// Mailbox counter of the device's own messages (1..7, wrapping 7 → 1; never 0).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MailboxCounter(u8);

impl MailboxCounter {
    /// The next counter value.
    pub fn advance(&mut self) -> u8 {
        self.0 = if self.0 >= 7 { 1 } else { self.0 + 1 };
        self.0
    }
}

/// Build a mailbox message: header (address 0, channel 0, priority 0) + body.
pub fn mailbox_message(ty: MailboxType, counter: u8, body: &[u8]) -> Vec<u8> {
    let h = MailboxHeader {
        length: body.len() as u16,
        address: 0,
        channel: 0,
        priority: 0,
        mailbox_type: ty,
        counter,
    };
    let mut v = h.encode().to_vec();
    v.extend_from_slice(body);
    v
}

/// Mailbox error reply (type 0): service 0x0001, detail code.
pub fn mailbox_error_message(counter: u8, detail: u16) -> Vec<u8> {
    let mut body = 0x0001u16.to_le_bytes().to_vec();
    body.extend_from_slice(&detail.to_le_bytes());
    mailbox_message(MailboxType::Error, counter, &body)
}

/// CoE server (SDO + EMCY) over a drive model and an object table.
#[derive(Debug)]
pub struct CoeServer {
    model: Box<dyn DriveModel>,
    entries: Vec<ObjectEntry>,
    mbx_size: usize,
    counter: MailboxCounter,
    last_request_counter: u8,
    upload: Option<Upload>,
    download: Option<Download>,
    outgoing: VecDeque<Vec<u8>>,
    delayed: VecDeque<(u32, Vec<u8>)>,
    last_model_error: u16,
    descriptions: OdDescriptions,
    /// PDO configuration rules (emulated vendor devices), checked before every download.
    pdo_rules: Option<super::pdo_rules::PdoRules>,
    /// SDO complete access supported (ESI `Mailbox/CoE@CompleteAccess`).
    complete_access: bool,
    /// Model-backed entries whose model object has another index: (entry, model object) — a
    /// vendor device's object that plays a CiA 402 object (e.g. 0x7010:03 → 0x6060).
    aliases: Vec<((u16, u8), (u16, u8))>,
    /// Fault knobs.
    pub faults: CoeFaults,
    /// Number of SDO requests handled.
    pub sdo_requests: usize,
    /// Number of SDO information requests handled.
    pub sdo_info_requests: usize,
}

/// Store `data` as an entry's value, in the entry's buffer when it has one (a PDO-mapped
/// object written every cycle allocates nothing).
fn store(slot: &mut Option<Vec<u8>>, data: &[u8]) {
    match slot {
        Some(d) => {
            d.clear();
            d.extend_from_slice(data);
        }
        None => *slot = Some(data.to_vec()),
    }
}

impl CoeServer {
    /// Server over `model` with the entries `entries`; `mailbox_size` is the size of the read
    /// (device → master) mailbox in bytes (SM1 length), which limits normal uploads and segment
    /// sizes.
    pub fn new(model: Box<dyn DriveModel>, entries: Vec<ObjectEntry>, mailbox_size: usize) -> Self {
        let last_model_error = model.last_error_code();
        let descriptions = OdDescriptions::from_entries(&entries);
        Self {
            model,
            entries,
            descriptions,
            pdo_rules: None,
            complete_access: true,
            aliases: Vec::new(),
            mbx_size: mailbox_size.max(16),
            counter: MailboxCounter::default(),
            last_request_counter: 0,
            upload: None,
            download: None,
            outgoing: VecDeque::new(),
            delayed: VecDeque::new(),
            last_model_error,
            faults: CoeFaults::default(),
            sdo_requests: 0,
            sdo_info_requests: 0,
        }
    }

    /// Does the device support SDO complete access (ESI `Mailbox/CoE@CompleteAccess`)? A server
    /// starts with it on; off, every CA upload or download is aborted with 0x06010000.
    pub fn set_complete_access(&mut self, on: bool) {
        self.complete_access = on;
    }

    /// Let the model-backed entry `entry` answer with the model's object `model` (a vendor
    /// device's object that plays a CiA 402 object of the drive model).
    pub fn alias(&mut self, entry: (u16, u8), model: (u16, u8)) {
        self.aliases.retain(|(e, _)| *e != entry);
        self.aliases.push((entry, model));
    }

    /// The model's object behind entry `index:sub`.
    fn model_object(&self, index: u16, sub: u8) -> (u16, u8) {
        self.aliases
            .iter()
            .find(|(e, _)| *e == (index, sub))
            .map_or((index, sub), |(_, m)| *m)
    }

    /// The descriptions the SDO information service gives.
    pub fn descriptions(&self) -> &OdDescriptions {
        &self.descriptions
    }

    /// Replace the descriptions (e.g. with [`OdDescriptions::from_esi`]).
    pub fn set_descriptions(&mut self, d: OdDescriptions) {
        self.descriptions = d;
    }

    /// Check every download against these PDO configuration rules
    /// ([`super::pdo_rules`]).
    pub fn set_pdo_rules(&mut self, rules: super::pdo_rules::PdoRules) {
        self.pdo_rules = Some(rules);
    }

    /// The PDO configuration rules, if the server has them.
    pub fn pdo_rules_mut(&mut self) -> Option<&mut super::pdo_rules::PdoRules> {
        self.pdo_rules.as_mut()
    }

    /// The drive model.
    pub fn model(&self) -> &dyn DriveModel {
        self.model.as_ref()
    }

    /// The drive model, mutable.
    pub fn model_mut(&mut self) -> &mut dyn DriveModel {
        self.model.as_mut()
    }

    /// Put a new drive model in (a device's application restarting, CiA 301 NMT reset node);
    /// returns the old one. The object entries stay.
    pub fn replace_model(&mut self, model: Box<dyn DriveModel>) -> Box<dyn DriveModel> {
        self.last_model_error = model.last_error_code();
        std::mem::replace(&mut self.model, model)
    }

    /// Bytes of a segmented download collected so far (at most [`SDO_DOWNLOAD_MAX`]).
    pub fn download_len(&self) -> usize {
        self.download.as_ref().map_or(0, |d| d.data.len())
    }

    /// End of a mailbox session (the device entered INIT): the request repeat counter and the
    /// device's own counter start again (ETG.1000.4 §5.6: after INIT the master's first request
    /// carries counter 1 and must not be taken for a repeat of the previous session's last
    /// one), transfers in progress are cancelled and queued messages dropped. The object
    /// dictionary and the model keep their values.
    pub fn reset_session(&mut self) {
        self.counter = MailboxCounter::default();
        self.last_request_counter = 0;
        self.upload = None;
        self.download = None;
        self.outgoing.clear();
        self.delayed.clear();
    }

    /// The object table.
    pub fn entries(&self) -> &[ObjectEntry] {
        &self.entries
    }

    /// Add or replace an entry.
    pub fn insert(&mut self, e: ObjectEntry) {
        self.entries
            .retain(|x| (x.index, x.sub) != (e.index, e.sub));
        self.entries.push(e);
    }

    /// Queue an emergency message (CoE service 1): error code, error register, 5 zero
    /// manufacturer bytes.
    pub fn emergency(&mut self, code: u16, register: u8) {
        self.emergency_with(code, register, [0; 5]);
    }

    /// Queue an emergency message with manufacturer-specific bytes.
    pub fn emergency_with(&mut self, code: u16, register: u8, manufacturer: [u8; 5]) {
        let m = self.emcy_message(code, register, manufacturer);
        self.outgoing.push_back(m);
    }

    fn emcy_message(&mut self, code: u16, register: u8, manufacturer: [u8; 5]) -> Vec<u8> {
        let mut body = CoeHeader {
            number: 0,
            service: CoeService::Emergency,
        }
        .encode()
        .to_vec();
        body.extend_from_slice(&code.to_le_bytes());
        body.push(register);
        body.extend_from_slice(&manufacturer);
        let c = self.counter.advance();
        mailbox_message(MailboxType::Coe, c, &body)
    }

    /// Device-initiated messages waiting for the read mailbox (EMCY, delayed answers that are
    /// due), oldest first; the caller passes them to [`super::Esc::push_mailbox`].
    pub fn take_outgoing(&mut self) -> Vec<Vec<u8>> {
        self.outgoing.drain(..).collect()
    }

    /// One mailbox poll: checks the model for a new fault (queues EMCY with the model's error
    /// code and error register 0x01), counts delayed answers down and returns everything due
    /// (see [`Self::take_outgoing`]).
    pub fn poll(&mut self) -> Vec<Vec<u8>> {
        self.check_model_fault();
        for d in self.delayed.iter_mut() {
            d.0 = d.0.saturating_sub(1);
        }
        while self.delayed.front().is_some_and(|d| d.0 == 0) {
            if let Some((_, m)) = self.delayed.pop_front() {
                self.outgoing.push_back(m);
            }
        }
        self.take_outgoing()
    }

    fn check_model_fault(&mut self) {
        let e = self.model.last_error_code();
        if e != self.last_model_error {
            self.last_model_error = e;
            if e != 0 {
                self.emergency(e, 0x01);
            }
        }
    }

    /// Handle one mailbox message from the write mailbox (full SM0 content incl. padding);
    /// returns the reply for the read mailbox, if one is due now.
    pub fn handle(&mut self, msg: &[u8]) -> Option<Vec<u8>> {
        let Ok((hdr, body)) = MailboxHeader::parse(msg) else {
            let detail = if msg.len() < MailboxHeader::LEN {
                mailbox_error::SIZE_TOO_SHORT
            } else {
                mailbox_error::SYNTAX
            };
            let c = self.counter.advance();
            return Some(mailbox_error_message(c, detail));
        };
        if hdr.counter != 0 && hdr.counter == self.last_request_counter {
            return None; // repeated request
        }
        self.last_request_counter = hdr.counter;
        if hdr.mailbox_type != MailboxType::Coe {
            let c = self.counter.advance();
            return Some(mailbox_error_message(
                c,
                mailbox_error::UNSUPPORTED_PROTOCOL,
            ));
        }
        let Ok((coe, rest)) = CoeHeader::parse(body) else {
            let c = self.counter.advance();
            return Some(mailbox_error_message(c, mailbox_error::INVALID_HEADER));
        };
        if coe.service == CoeService::SdoInformation {
            self.sdo_info_requests += 1;
            // The data of a fragment: read mailbox − mailbox header − CoE header − SDO info header.
            let max = self.mbx_size - MailboxHeader::LEN - CoeHeader::LEN - 4;
            let mut bodies = self.descriptions.respond(rest, max).into_iter();
            let first = bodies.next()?;
            let c = self.counter.advance();
            let reply = mailbox_message(MailboxType::Coe, c, &first);
            for b in bodies {
                let c = self.counter.advance();
                self.outgoing
                    .push_back(mailbox_message(MailboxType::Coe, c, &b));
            }
            return Some(reply);
        }
        if coe.service != CoeService::SdoRequest {
            let c = self.counter.advance();
            return Some(mailbox_error_message(
                c,
                mailbox_error::SERVICE_NOT_SUPPORTED,
            ));
        }
        self.sdo_requests += 1;
        let reply_body = match SdoFrame::parse(rest, SdoDirection::Request) {
            Ok(f) if f.command == SdoCommand::Abort => {
                self.upload = None;
                self.download = None;
                return None;
            }
            Ok(f) => self.sdo(&f),
            Err(_) => abort_body(0, 0, abort::UNKNOWN_COMMAND),
        };
        self.check_model_fault();
        let mut first = None;
        if let Some((code, reg)) = self.faults.emcy_before_next_sdo.take() {
            first = Some(self.emcy_message(code, reg, [0; 5]));
        }
        let c = self.counter.advance();
        let reply = mailbox_message(MailboxType::Coe, c, &reply_body);
        if self.faults.delay_polls > 0 {
            self.delayed.push_back((self.faults.delay_polls, reply));
            return first;
        }
        match first {
            Some(e) => {
                self.outgoing.push_back(reply);
                Some(e)
            }
            None => Some(reply),
        }
    }

    /// Read object `index:sub` as bytes (the object dictionary without the CoE framing, e.g.
    /// for a CANopen SDO server); `Err` is the CiA 301 abort code.
    pub fn read(&self, index: u16, sub: u8) -> Result<Vec<u8>, u32> {
        self.read_with(index, sub, <[u8]>::to_vec)
    }

    /// [`read`](Self::read) without a copy: `f` sees the object's bytes (the node's cyclic
    /// work reads its communication objects this way and allocates nothing).
    pub fn read_with<R>(&self, index: u16, sub: u8, f: impl FnOnce(&[u8]) -> R) -> Result<R, u32> {
        let i = self.find(index, sub)?;
        self.read_entry_with(i, f)
    }

    /// Write object `index:sub` from bytes (data type and access checked); `Err` is the CiA 301
    /// abort code.
    pub fn write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
        let i = self.find(index, sub)?;
        self.write_entry(i, data)
    }

    fn find(&self, index: u16, sub: u8) -> Result<usize, u32> {
        if let Some(i) = self
            .entries
            .iter()
            .position(|e| e.index == index && e.sub == sub)
        {
            return Ok(i);
        }
        if self.entries.iter().any(|e| e.index == index) {
            Err(abort::NO_SUB_INDEX)
        } else {
            Err(abort::NO_OBJECT)
        }
    }

    fn subs_of(&self, index: u16, from: u8) -> Vec<usize> {
        let mut v: Vec<usize> = (0..self.entries.len())
            .filter(|&i| self.entries[i].index == index && self.entries[i].sub >= from)
            .collect();
        v.sort_by_key(|&i| self.entries[i].sub);
        v
    }

    fn read_entry(&self, i: usize) -> Result<Vec<u8>, u32> {
        self.read_entry_with(i, <[u8]>::to_vec)
    }

    /// Entry `i`'s bytes (stored, or the model's value in the entry's type, as
    /// [`DataType::encode`] gives them) to `f`.
    fn read_entry_with<R>(&self, i: usize, f: impl FnOnce(&[u8]) -> R) -> Result<R, u32> {
        let e = &self.entries[i];
        if e.access == Access::Wo {
            return Err(abort::WRITE_ONLY);
        }
        if let Some(d) = &e.data {
            return Ok(f(d));
        }
        let (index, sub) = self.model_object(e.index, e.sub);
        let v = self.model.read_object(index, sub)?;
        let n = e.ty.size().unwrap_or(8);
        Ok(f(&v.to_le_bytes()[..n]))
    }

    fn write_entry(&mut self, i: usize, data: &[u8]) -> Result<(), u32> {
        if let Some(r) = &self.pdo_rules {
            let e = &self.entries[i];
            r.check(self, e.index, e.sub, data)?;
        }
        let e = &self.entries[i];
        if e.access == Access::Ro {
            return Err(abort::READ_ONLY);
        }
        match e.ty {
            DataType::Bytes(max) => {
                if data.len() > max {
                    return Err(abort::LENGTH);
                }
                store(&mut self.entries[i].data, data);
                Ok(())
            }
            ty => {
                let v = ty.decode(data).ok_or(abort::LENGTH)?;
                if e.data.is_some() {
                    store(&mut self.entries[i].data, data);
                    return Ok(());
                }
                let (index, sub) = self.model_object(e.index, e.sub);
                self.model.write_object(index, sub, v)
            }
        }
    }

    /// Complete-access image of `index` from `sub` (0 or 1); sub 0 padded to 16 bits.
    fn read_complete(&self, index: u16, sub: u8) -> Result<Vec<u8>, u32> {
        if sub > 1 || !self.complete_access {
            return Err(abort::UNSUPPORTED_ACCESS);
        }
        self.find(index, sub)?;
        let mut out = Vec::new();
        for i in self.subs_of(index, sub) {
            let mut d = self.read_entry(i)?;
            if self.entries[i].sub == 0 {
                d.resize(2, 0);
            }
            out.extend_from_slice(&d);
        }
        Ok(out)
    }

    /// Complete-access download to `index` from `sub` (ETG.1000.6 §5.6.2.1.2, "complete
    /// access"): from sub-index 0 the data is sub-index 0 as 16 bits (its value n, padding)
    /// followed by sub-indices 1 … n (and, if the data goes on, the entries after n up to the
    /// whole object, as an upload gives it); from sub-index 1, sub-indices 1 … in order, as many
    /// as the data holds. Read-only entries are skipped. The value n is what TwinCAT and SOEM write
    /// to set a PDO assignment (0x1C12 / 0x1C13) or mapping in one request: it is applied the
    /// CiA 301 way — sub-index 0 = 0, the entries, sub-index 0 = n — each step under the PDO
    /// rules of an emulated vendor device, so the request is accepted or refused exactly as the
    /// single writes would be; on a refusal the object's old entries are put back.
    fn write_complete(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
        if sub > 1 || !self.complete_access {
            return Err(abort::UNSUPPORTED_ACCESS);
        }
        self.find(index, sub)?;
        let subs = self.subs_of(index, 0);
        let has_sub0 = subs.first().is_some_and(|&i| self.entries[i].sub == 0);
        let (count, mut pos) = if sub == 0 {
            if !has_sub0 {
                return Err(abort::UNSUPPORTED_ACCESS);
            }
            let n = *data.first().ok_or(abort::LENGTH)?;
            if data.len() < 2 {
                return Err(abort::LENGTH);
            }
            (Some(n), 2usize)
        } else {
            (None, 0usize)
        };
        // The entries the data holds, with their bytes.
        let mut parts: Vec<(usize, &[u8])> = Vec::new();
        let entries: Vec<usize> = subs
            .iter()
            .copied()
            .filter(|&i| self.entries[i].sub >= 1)
            .collect();
        for (k, &i) in entries.iter().enumerate() {
            if pos >= data.len() {
                break;
            }
            let e = &self.entries[i];
            let n = match e.ty.size() {
                Some(n) => n,
                None if k + 1 == entries.len() => data.len() - pos,
                None => return Err(abort::UNSUPPORTED_ACCESS),
            };
            let part = data.get(pos..pos + n).ok_or(abort::LENGTH)?;
            parts.push((i, part));
            pos += n;
        }
        // The data may go on past entry n up to the whole object, as a complete-access upload
        // hands it out: entries above n are written too (they hold no mapping until sub-index 0
        // says so), so an uploaded image can be downloaded back unchanged.
        if pos != data.len() || count.is_some_and(|n| usize::from(n) > parts.len()) {
            return Err(abort::LENGTH);
        }
        let Some(n) = count else {
            for (i, part) in parts {
                if self.entries[i].access != Access::Ro {
                    self.write_entry(i, part)?;
                }
            }
            return Ok(());
        };
        let sub0 = subs[0];
        if self.entries[sub0].access == Access::Ro {
            // A fixed object: accepted when it says what the object holds already.
            for (i, part) in &parts {
                if self.read_entry(*i)? != *part {
                    return Err(abort::READ_ONLY);
                }
            }
            return if self.read_entry(sub0)?.first() == Some(&n) {
                Ok(())
            } else {
                Err(abort::READ_ONLY)
            };
        }
        let old: Vec<(usize, Vec<u8>)> = subs
            .iter()
            .map(|&i| Ok((i, self.read_entry(i)?)))
            .collect::<Result<_, u32>>()?;
        let apply = |this: &mut Self| -> Result<(), u32> {
            this.write_entry(sub0, &[0])?;
            for (i, part) in &parts {
                if this.entries[*i].access != Access::Ro {
                    this.write_entry(*i, part)?;
                }
            }
            this.write_entry(sub0, &[n])
        };
        if let Err(code) = apply(self) {
            // Put the old content back, without the rules (it was the device's own).
            for (i, d) in old {
                if self.entries[i].data.is_some() {
                    store(&mut self.entries[i].data, &d);
                }
            }
            return Err(code);
        }
        Ok(())
    }

    fn sdo(&mut self, f: &SdoFrame<'_>) -> Vec<u8> {
        let index = f.index.unwrap_or(0);
        let sub = f.subindex.unwrap_or(0);
        match f.command {
            SdoCommand::InitiateUploadRequest { complete_access } => {
                self.upload = None;
                self.download = None;
                let data = if complete_access {
                    self.read_complete(index, sub)
                } else {
                    self.find(index, sub).and_then(|i| self.read_entry(i))
                };
                match data {
                    Ok(d) => self.upload_response(index, sub, complete_access, d),
                    Err(code) => abort_body(index, sub, code),
                }
            }
            SdoCommand::UploadSegmentRequest { toggle } => {
                let Some(mut up) = self.upload.take() else {
                    return abort_body(0, 0, abort::UNKNOWN_COMMAND);
                };
                if toggle != up.toggle {
                    return abort_body(up.index, up.sub, abort::TOGGLE);
                }
                let max = self.mbx_size - MailboxHeader::LEN - CoeHeader::LEN - 1;
                let n = (up.data.len() - up.pos).min(max);
                let chunk = &up.data[up.pos..up.pos + n];
                up.pos += n;
                let last = up.pos >= up.data.len();
                let unused = 7usize.saturating_sub(n) as u8;
                let mut body = coe_sdo_header(CoeService::SdoResponse);
                body.push(
                    SdoCommand::UploadSegmentResponse {
                        toggle,
                        unused,
                        last,
                    }
                    .encode(),
                );
                body.extend_from_slice(chunk);
                body.resize(body.len() + usize::from(unused), 0);
                if !last {
                    up.toggle = !up.toggle;
                    self.upload = Some(up);
                }
                body
            }
            SdoCommand::InitiateDownloadRequest {
                complete_access,
                expedited,
                size_indicated,
                unused,
            } => {
                self.upload = None;
                self.download = None;
                if expedited {
                    let n = if size_indicated {
                        4 - usize::from(unused)
                    } else {
                        self.find(index, sub)
                            .ok()
                            .and_then(|i| self.entries[i].ty.size())
                            .unwrap_or(4)
                            .min(4)
                    };
                    let d = f.data.get(..n).unwrap_or(f.data).to_vec();
                    return self.finish_download(index, sub, complete_access, &d);
                }
                let Some(sz) = f.data.get(..4) else {
                    return abort_body(index, sub, abort::LENGTH);
                };
                let size = u32::from_le_bytes([sz[0], sz[1], sz[2], sz[3]]) as usize;
                if size > SDO_DOWNLOAD_MAX {
                    return abort_body(index, sub, abort::OUT_OF_MEMORY);
                }
                let payload = &f.data[4..];
                if payload.len() >= size {
                    let d = payload[..size].to_vec();
                    return self.finish_download(index, sub, complete_access, &d);
                }
                // Segmented: check the target now (CiA 301 lets the server abort early).
                if complete_access && !self.complete_access {
                    return abort_body(index, sub, abort::UNSUPPORTED_ACCESS);
                }
                if !complete_access {
                    match self.find(index, sub) {
                        Ok(i) if self.entries[i].access == Access::Ro => {
                            return abort_body(index, sub, abort::READ_ONLY)
                        }
                        Ok(_) => {}
                        Err(code) => return abort_body(index, sub, code),
                    }
                }
                self.download = Some(Download {
                    index,
                    sub,
                    complete_access,
                    size,
                    data: payload.to_vec(),
                    toggle: false,
                });
                download_response(index, sub)
            }
            SdoCommand::DownloadSegmentRequest {
                toggle,
                unused,
                last,
            } => {
                let Some(mut dl) = self.download.take() else {
                    return abort_body(0, 0, abort::UNKNOWN_COMMAND);
                };
                if toggle != dl.toggle {
                    return abort_body(dl.index, dl.sub, abort::TOGGLE);
                }
                let n = f.data.len().saturating_sub(usize::from(unused));
                dl.data.extend_from_slice(&f.data[..n]);
                if dl.data.len() > dl.size {
                    return abort_body(dl.index, dl.sub, abort::LENGTH);
                }
                if last {
                    if dl.data.len() != dl.size {
                        return abort_body(dl.index, dl.sub, abort::LENGTH);
                    }
                    let r = if dl.complete_access {
                        self.write_complete(dl.index, dl.sub, &dl.data)
                    } else {
                        self.find(dl.index, dl.sub)
                            .and_then(|i| self.write_entry(i, &dl.data))
                    };
                    if let Err(code) = r {
                        return abort_body(dl.index, dl.sub, code);
                    }
                } else {
                    dl.toggle = !dl.toggle;
                    self.download = Some(dl);
                }
                let mut body = coe_sdo_header(CoeService::SdoResponse);
                body.push(SdoCommand::DownloadSegmentResponse { toggle }.encode());
                body.extend_from_slice(&[0; 7]);
                body
            }
            _ => {
                // Unknown specifier: echo index/sub from the request layout if present.
                let (index, sub) = match f.data {
                    [lo, hi, sub, ..] if f.index.is_none() => {
                        (u16::from_le_bytes([*lo, *hi]), *sub)
                    }
                    _ => (index, sub),
                };
                abort_body(index, sub, abort::UNKNOWN_COMMAND)
            }
        }
    }

    fn finish_download(&mut self, index: u16, sub: u8, ca: bool, d: &[u8]) -> Vec<u8> {
        let r = if ca {
            self.write_complete(index, sub, d)
        } else {
            self.find(index, sub).and_then(|i| self.write_entry(i, d))
        };
        match r {
            Ok(()) => download_response(index, sub),
            Err(code) => abort_body(index, sub, code),
        }
    }

    fn upload_response(&mut self, index: u16, sub: u8, ca: bool, d: Vec<u8>) -> Vec<u8> {
        let mut body = coe_sdo_header(CoeService::SdoResponse);
        let idx = index.to_le_bytes();
        if d.len() <= 4 && !ca {
            let unused = (4 - d.len()) as u8;
            body.push(
                SdoCommand::InitiateUploadResponse {
                    complete_access: false,
                    expedited: true,
                    size_indicated: true,
                    unused,
                }
                .encode(),
            );
            body.extend_from_slice(&[idx[0], idx[1], sub]);
            body.extend_from_slice(&d);
            body.resize(10, 0);
            return body;
        }
        body.push(
            SdoCommand::InitiateUploadResponse {
                complete_access: ca,
                expedited: false,
                size_indicated: true,
                unused: 0,
            }
            .encode(),
        );
        body.extend_from_slice(&[idx[0], idx[1], sub]);
        body.extend_from_slice(&(d.len() as u32).to_le_bytes());
        if MailboxHeader::LEN + body.len() + d.len() <= self.mbx_size {
            body.extend_from_slice(&d);
        } else {
            self.upload = Some(Upload {
                index,
                sub,
                data: d,
                pos: 0,
                toggle: false,
            });
        }
        body
    }
}

fn coe_sdo_header(service: CoeService) -> Vec<u8> {
    CoeHeader { number: 0, service }.encode().to_vec()
}

fn download_response(index: u16, sub: u8) -> Vec<u8> {
    let mut body = coe_sdo_header(CoeService::SdoResponse);
    body.push(SdoCommand::InitiateDownloadResponse.encode());
    let i = index.to_le_bytes();
    body.extend_from_slice(&[i[0], i[1], sub, 0, 0, 0, 0]);
    body
}

/// CoE body of an SDO abort request (service 2, command 0x80, index, sub, code).
pub fn abort_body(index: u16, sub: u8, code: u32) -> Vec<u8> {
    let mut body = coe_sdo_header(CoeService::SdoRequest);
    body.push(SdoCommand::Abort.encode());
    let i = index.to_le_bytes();
    body.extend_from_slice(&[i[0], i[1], sub]);
    body.extend_from_slice(&code.to_le_bytes());
    body
}

impl EscApplication for CoeServer {
    fn coe_mut(&mut self) -> Option<&mut CoeServer> {
        Some(self)
    }

    fn mailbox_received(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        self.handle(data)
    }

    fn mailbox_reset(&mut self) {
        self.reset_session();
    }
}

#[cfg(test)]
mod tests {
    //! Complete access (ETG.1000.6 §5.6.2.1.2) over the mailbox, bytes built here from the
    //! standard's layouts: mailbox header (length, address, channel/priority, type 3 = CoE |
    //! counter << 4), CoE header (service 2 = SDO request << 12), SDO command byte, index,
    //! sub-index, 4 data / size bytes.

    use super::*;
    use crate::drive::catalogue;
    use crate::drive::model::ds402::Ds402Model;

    fn server(complete_access: bool) -> CoeServer {
        let def = catalogue::builtin("cia402-generic").expect("built-in drive");
        let mut entries = ds402_objects("ca test");
        let rw = |index, sub, ty, v| ObjectEntry {
            access: Access::Rw,
            ..ObjectEntry::constant(index, sub, ty, v)
        };
        // 0x1C12 = [0x1600, 0x1601], 4 entries capacity; 0x1600 = two entries.
        entries.push(rw(0x1C12, 0, DataType::U8, 2));
        entries.push(rw(0x1C12, 1, DataType::U16, 0x1600));
        entries.push(rw(0x1C12, 2, DataType::U16, 0x1601));
        entries.push(rw(0x1C12, 3, DataType::U16, 0));
        entries.push(rw(0x1600, 0, DataType::U8, 2));
        entries.push(rw(0x1600, 1, DataType::U32, 0x6040_0010));
        entries.push(rw(0x1600, 2, DataType::U32, 0x607A_0020));
        let mut s = CoeServer::new(Box::new(Ds402Model::new(&def)), entries, 128);
        s.set_complete_access(complete_access);
        s
    }

    /// A CoE SDO request with mailbox counter `counter`.
    fn request(counter: u8, sdo: &[u8]) -> Vec<u8> {
        let mut m = Vec::new();
        let len = (2 + sdo.len()) as u16;
        m.extend_from_slice(&len.to_le_bytes());
        m.extend_from_slice(&[0, 0, 0, 0x03 | (counter << 4)]);
        m.extend_from_slice(&(2u16 << 12).to_le_bytes());
        m.extend_from_slice(sdo);
        m
    }

    /// The SDO part of a reply (after mailbox and CoE headers).
    fn sdo_of(reply: &[u8]) -> &[u8] {
        &reply[8..]
    }

    fn upload_ca(s: &mut CoeServer, counter: u8, index: u16, sub: u8) -> Vec<u8> {
        let i = index.to_le_bytes();
        // ccs 2 (initiate upload) << 5 | CA bit 4.
        let r = s
            .handle(&request(counter, &[0x50, i[0], i[1], sub, 0, 0, 0, 0]))
            .expect("reply");
        sdo_of(&r).to_vec()
    }

    #[test]
    fn complete_access_upload_from_sub_0_and_1() {
        let mut s = server(true);
        let r = upload_ca(&mut s, 1, 0x1C12, 0);
        // scs 2 << 5 | CA | size indicated (0x01), not expedited: 0x51; size 2 + 3 × 2 = 8.
        assert_eq!(r[0], 0x51, "{r:02x?}");
        assert_eq!(&r[1..4], &[0x12, 0x1C, 0]);
        assert_eq!(u32::from_le_bytes([r[4], r[5], r[6], r[7]]), 8);
        assert_eq!(&r[8..16], &[2, 0, 0x00, 0x16, 0x01, 0x16, 0, 0]);
        let r = upload_ca(&mut s, 2, 0x1600, 1);
        assert_eq!(u32::from_le_bytes([r[4], r[5], r[6], r[7]]), 8);
        assert_eq!(&r[8..16], &[0x10, 0, 0x40, 0x60, 0x20, 0, 0x7A, 0x60]);
    }

    #[test]
    fn complete_access_download_then_upload() {
        let mut s = server(true);
        // Normal download with CA from sub 0: ccs 1 << 5 | CA | size indicated = 0x31, size 4:
        // sub 0 = 1 (16 bits), sub 1 = 0x1601.
        let mut req = vec![0x31, 0x12, 0x1C, 0, 4, 0, 0, 0];
        req.extend_from_slice(&[1, 0, 0x01, 0x16]);
        let r = s.handle(&request(1, &req)).expect("reply");
        assert_eq!(
            sdo_of(&r)[0],
            0x60,
            "download response, not an abort: {r:02x?}"
        );
        assert_eq!(s.read(0x1C12, 0).unwrap(), vec![1]);
        assert_eq!(s.read(0x1C12, 1).unwrap(), vec![0x01, 0x16]);
        let r = upload_ca(&mut s, 2, 0x1C12, 0);
        assert_eq!(&r[8..10], &[1, 0]);
        assert_eq!(&r[10..12], &[0x01, 0x16]);
        // The whole image an upload gives (count 2, then every entry, the spare one 0) goes
        // back unchanged.
        let mut req = vec![0x31, 0x12, 0x1C, 0, 8, 0, 0, 0];
        req.extend_from_slice(&[2, 0, 0x00, 0x16, 0x01, 0x16, 0, 0]);
        let r = s.handle(&request(4, &req)).expect("reply");
        assert_eq!(sdo_of(&r)[0], 0x60, "whole image accepted: {r:02x?}");
        assert_eq!(s.read(0x1C12, 0).unwrap(), vec![2]);
        assert_eq!(s.read(0x1C12, 2).unwrap(), vec![0x01, 0x16]);
        // Fewer entries than the count, or a length between entries: abort 0x06070010, object
        // unchanged.
        let mut req = vec![0x31, 0x12, 0x1C, 0, 4, 0, 0, 0];
        req.extend_from_slice(&[2, 0, 0x00, 0x16]);
        let r = s.handle(&request(5, &req)).expect("reply");
        assert_eq!(sdo_of(&r)[0], 0x80);
        assert_eq!(&sdo_of(&r)[4..8], &abort::LENGTH.to_le_bytes());
        let mut req = vec![0x31, 0x12, 0x1C, 0, 5, 0, 0, 0];
        req.extend_from_slice(&[1, 0, 0x00, 0x16, 0x01]);
        let r = s.handle(&request(6, &req)).expect("reply");
        assert_eq!(&sdo_of(&r)[4..8], &abort::LENGTH.to_le_bytes());
        assert_eq!(s.read(0x1C12, 0).unwrap(), vec![2]);
    }

    #[test]
    fn complete_access_refused_where_the_esi_does_not_declare_it() {
        let mut s = server(false);
        let r = upload_ca(&mut s, 1, 0x1C12, 0);
        assert_eq!(r[0], 0x80, "abort: {r:02x?}");
        assert_eq!(&r[4..8], &abort::UNSUPPORTED_ACCESS.to_le_bytes());
        let mut req = vec![0x31, 0x12, 0x1C, 0, 4, 0, 0, 0];
        req.extend_from_slice(&[1, 0, 0x00, 0x16]);
        let r = s.handle(&request(2, &req)).expect("reply");
        assert_eq!(&sdo_of(&r)[4..8], &abort::UNSUPPORTED_ACCESS.to_le_bytes());
        assert_eq!(s.read(0x1C12, 0).unwrap(), vec![2], "unchanged");
        // Ordinary access still works.
        let r = s
            .handle(&request(3, &[0x40, 0x12, 0x1C, 0, 0, 0, 0, 0]))
            .expect("reply");
        assert_eq!(sdo_of(&r)[0] & 0xE0, 0x40, "upload response: {r:02x?}");
    }
}
