//! CoE mailbox client on ethercrab's public raw command API (`Command::fprd` / `fpwr`).
//!
//! Works around the ethercrab 0.7.1 CoE defects (reproduced against the emulated servo):
//! spec-conformant segmented upload with toggle check, normal and segmented download
//! (> 4 bytes), and CoE emergency messages arriving instead of the SDO response are collected
//! ([`CoeClient::take_emergencies`]) while the client keeps waiting for the real response.
//! Mailbox handling (ETG.1000.4 mailbox, ETG.1000.6 CoE): SM1 status (0x080D bit 3 = mailbox full) is read
//! before the read mailbox, requests are padded to the full SM0 length, the mailbox counter
//! runs 1..7. Every wait is bounded by [`CoeClient::timeout`]. That mailbox handling is the
//! protocol-neutral [`MailboxTransport`], shared with the SoE client ([`super::soe`]).

use std::time::{Duration, Instant};

use ethercrab::{Command, MainDevice};

use super::sdo_info;
use super::wire::{
    CoeHeader, CoeService, MailboxHeader, MailboxType, SdoCommand, SdoDirection, SdoFrame,
    SdoInfoOpcode,
};

/// First sync manager register (SM0 start address; ETG.1000.4 register 0x0800).
const SM_REGISTERS: u16 = 0x0800;
/// SM0 (write mailbox) status register.
const SM0_STATUS: u16 = 0x0805;
/// SM1 (read mailbox) status register.
const SM1_STATUS: u16 = 0x080D;
/// Mailbox-full bit of a sync manager status register.
const MBX_FULL: u8 = 0x08;

/// Default bound of one whole mailbox transfer (all its segments or fragments): 10 s. Each
/// wait has its own bound ([`MailboxTransport::timeout`], 2 s); this one ends a transfer whose
/// device answers every request in time but never finishes (issue 28 item 1). An EtherCAT
/// mailbox round trip takes a few ms, so 10 s carries even a 1 MiB object
/// ([`crate::limits::MAX_MAILBOX_OBJECT_BYTES`]) through a 128-byte mailbox.
pub const DEFAULT_TRANSFER_TIMEOUT: Duration = Duration::from_secs(10);

/// Errors of the mailbox clients ([`CoeClient`], [`super::soe::SoeClient`]).
#[derive(Debug, thiserror::Error)]
pub enum MailboxError {
    /// The device aborted the transfer.
    #[error("SDO {index:#06x}:{sub} aborted: {code:#010x} ({text})")]
    Abort {
        /// Object index.
        index: u16,
        /// Subindex.
        sub: u8,
        /// CiA 301 abort code.
        code: u32,
        /// The abort code in words.
        text: &'static str,
    },
    /// No (matching) response within the timeout.
    #[error("mailbox timeout after {0:?} ({1})")]
    Timeout(Duration, &'static str),
    /// A transfer that the device kept answering but never finished within its bound
    /// ([`CoeClient::transfer_timeout`], [`super::soe::SoeClient::transfer_timeout`];
    /// issue 28 item 1). For an SDO the client sent abort 0x05040000.
    #[error("{what} not finished after {after:?} although the device kept answering ({progress})")]
    TransferTimeout {
        /// The transfer: "SDO 0x2000:01 upload", "SDO information OD list" …
        what: String,
        /// Time since the request.
        after: Duration,
        /// What came, and the abort sent, in words.
        progress: String,
    },
    /// ethercrab datagram error.
    #[error("datagram: {0}")]
    Datagram(String),
    /// Malformed or unexpected response.
    #[error("protocol: {0}")]
    Protocol(String),
    /// Mailbox error reply (type 0) with its detail code ([`mailbox_error_text`]).
    #[error("mailbox error reply, detail {0:#06x} ({text})", text = mailbox_error_text(*.0))]
    MailboxErrorReply(u16),
    /// Request does not fit the write mailbox.
    #[error("request does not fit the write mailbox ({0} bytes)")]
    TooLarge(usize),
    /// The device offers an object larger than the client accepts
    /// ([`crate::limits::MAX_MAILBOX_OBJECT_BYTES`]).
    #[error("the device offers an object of {size} bytes; at most {limit} bytes are accepted")]
    ObjectTooLarge {
        /// Size announced or reached (bytes).
        size: usize,
        /// The cap (bytes).
        limit: usize,
    },
    /// SoE error reply (SoE header error bit, ETG.1000.6) with its SERCOS error
    /// code.
    #[error(
        "SoE {name} (drive {drive_no}): error {code:#06x} ({text})",
        name = crate::drive::sercos::idn_name(*.idn)
    )]
    Soe {
        /// IDN of the request.
        idn: u16,
        /// Drive number of the request.
        drive_no: u8,
        /// SERCOS error code (IEC 61800-7-204).
        code: u16,
        /// The error code in words ([`super::soe::error_text`]).
        text: &'static str,
    },
    /// The device answered an SDO Information request with an SDO Info Error (ETG.1000.6,
    /// opcode 7) carrying a CiA 301 abort code.
    #[error("SDO information for {what}: refused with {code:#010x} ({text})")]
    SdoInfo {
        /// The request (`OD list`, `object 0x6040`, `entry 0x6040:00`).
        what: String,
        /// CiA 301 abort code.
        code: u32,
        /// The abort code in words.
        text: &'static str,
    },
    /// The device does not offer the SDO Information service (mailbox error reply
    /// "service not supported", or no CoE).
    #[error(
        "the device does not support the CoE SDO Information service (mailbox error {0:#06x})"
    )]
    NoSdoInfo(u16),
    /// A value does not fit the data length / signedness of its target (checked before
    /// anything is sent).
    #[error(
        "value {value} does not fit {len} byte(s) {}",
        if *.signed { "signed" } else { "unsigned" }
    )]
    ValueOutOfRange {
        /// The value.
        value: i64,
        /// Data length in bytes.
        len: usize,
        /// Signed data type.
        signed: bool,
    },
}

/// A CoE emergency message received while waiting for an SDO response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Emergency {
    /// Error code.
    pub code: u16,
    /// Error register (0x1001).
    pub register: u8,
    /// Manufacturer-specific bytes.
    pub data: [u8; 5],
}

/// CiA 301 SDO abort code in words (CoE uses the CiA 301 codes; defined in [`crate::bus::abort`]).
pub use crate::bus::abort::abort_text;

/// Standard mailbox transport to one SubDevice over ethercrab's raw commands (ETG.1000.4 mailbox): the
/// write mailbox (SM0) and read mailbox (SM1) areas, the mailbox counter (1..7), a stale read
/// mailbox flushed before each request, requests padded to the full SM0 length, replies
/// awaited by polling the SM1 status (bit 3 = mailbox full) and read with the full SM1 length.
///
/// The protocol clients ([`CoeClient`], [`super::soe::SoeClient`]) are built on it; they can
/// share one transport (and so one counter) through their `from_transport` /
/// `into_transport`. CoE emergencies arriving in the read mailbox, whatever protocol the
/// caller waits for, are collected ([`MailboxTransport::take_emergencies`]).
#[derive(Debug)]
pub struct MailboxTransport {
    station: u16,
    mbx_out: (u16, u16),
    mbx_in: (u16, u16),
    counter: u8,
    emergencies: Vec<Emergency>,
    /// Bound for each wait (mailbox free, response).
    pub timeout: Duration,
}

fn dg(e: ethercrab::error::Error) -> MailboxError {
    MailboxError::Datagram(e.to_string())
}

impl MailboxTransport {
    /// Transport to the SubDevice at configured `station_address`, with the write mailbox
    /// (SM0) and read mailbox (SM1) as (start address, length). Timeout 2 s.
    pub fn new(station_address: u16, mbx_out: (u16, u16), mbx_in: (u16, u16)) -> Self {
        Self {
            station: station_address,
            mbx_out,
            mbx_in,
            counter: 0,
            emergencies: Vec::new(),
            timeout: Duration::from_secs(2),
        }
    }

    /// Transport to the SubDevice at configured `station_address`, its mailbox areas read from
    /// the device: the sync manager registers at 0x0800 (ETG.1000.4, 8 bytes per SM: start
    /// address, length, control) must show SM0 and SM1 in mailbox mode (control bits 1..0 =
    /// 10b), as they are from PRE-OP on. This is how a user who owns the ethercrab
    /// `MainDevice` gets a transport for a `SubDevice` (`SubDeviceRef::configured_address`).
    ///
    /// # Errors
    /// The register read failed ([`MailboxError::Datagram`]), or the device has no mailbox
    /// ([`MailboxError::Protocol`]).
    pub async fn discover(md: &MainDevice<'_>, station_address: u16) -> Result<Self, MailboxError> {
        let regs = Command::fprd(station_address, SM_REGISTERS)
            .receive::<[u8; 16]>(md)
            .await
            .map_err(dg)?;
        let sm = |o: usize| {
            (
                u16::from_le_bytes([regs[o], regs[o + 1]]),
                u16::from_le_bytes([regs[o + 2], regs[o + 3]]),
            )
        };
        let mailbox_mode = |o: usize| regs[o + 4] & 0x03 == 0x02;
        let (out, inp) = (sm(0), sm(8));
        if !mailbox_mode(0) || !mailbox_mode(8) || out.1 == 0 || inp.1 == 0 {
            return Err(MailboxError::Protocol(format!(
                "SubDevice {station_address:#06x} has no mailbox (SM0 / SM1 not in mailbox mode)"
            )));
        }
        Ok(Self::new(station_address, out, inp))
    }

    /// Configured station address of the SubDevice.
    pub fn station_address(&self) -> u16 {
        self.station
    }

    /// Write mailbox (SM0) length in bytes, mailbox header included.
    pub fn write_mailbox_len(&self) -> usize {
        usize::from(self.mbx_out.1)
    }

    /// Read mailbox (SM1) length in bytes, mailbox header included.
    pub fn read_mailbox_len(&self) -> usize {
        usize::from(self.mbx_in.1)
    }

    /// Largest service body ([`send`](Self::send)) that fits the write mailbox.
    pub fn max_body_len(&self) -> usize {
        self.write_mailbox_len().saturating_sub(MailboxHeader::LEN)
    }

    /// Emergencies received so far (drains the list).
    pub fn take_emergencies(&mut self) -> Vec<Emergency> {
        std::mem::take(&mut self.emergencies)
    }

    fn next_counter(&mut self) -> u8 {
        self.counter = if self.counter >= 7 {
            1
        } else {
            self.counter + 1
        };
        self.counter
    }

    async fn sm_status(&self, md: &MainDevice<'_>, reg: u16) -> Result<u8, MailboxError> {
        Command::fprd(self.station, reg)
            .receive::<u8>(md)
            .await
            .map_err(dg)
    }

    async fn read_mailbox(&self, md: &MainDevice<'_>) -> Result<Vec<u8>, MailboxError> {
        let r = Command::fprd(self.station, self.mbx_in.0)
            .receive_slice(md, self.mbx_in.1)
            .await
            .map_err(dg)?;
        Ok(r.to_vec())
    }

    /// Flush a stale read mailbox (emergencies in it are collected), wait for the write
    /// mailbox to be free, write `body` (service header + data) of protocol `mailbox_type`
    /// behind a mailbox header, padded to the full SM0 length.
    pub async fn send(
        &mut self,
        md: &MainDevice<'_>,
        mailbox_type: MailboxType,
        body: &[u8],
    ) -> Result<(), MailboxError> {
        let len = self.write_mailbox_len();
        if body.len() + MailboxHeader::LEN > len {
            return Err(MailboxError::TooLarge(body.len()));
        }
        let deadline = Instant::now() + self.timeout;
        // Stale messages in SM1 (e.g. an old EMCY) are read and collected.
        for _ in 0..10 {
            if self.sm_status(md, SM1_STATUS).await? & MBX_FULL == 0 {
                break;
            }
            let m = self.read_mailbox(md).await?;
            self.collect_emergency(&m);
        }
        while self.sm_status(md, SM0_STATUS).await? & MBX_FULL != 0 {
            if Instant::now() > deadline {
                return Err(MailboxError::Timeout(self.timeout, "write mailbox busy"));
            }
        }
        let hdr = MailboxHeader {
            length: body.len() as u16,
            address: 0,
            channel: 0,
            priority: 0,
            mailbox_type,
            counter: self.next_counter(),
        };
        let mut buf = vec![0u8; len];
        buf[..MailboxHeader::LEN].copy_from_slice(&hdr.encode());
        buf[MailboxHeader::LEN..MailboxHeader::LEN + body.len()].copy_from_slice(body);
        Command::fpwr(self.station, self.mbx_out.0)
            .send(md, buf.as_slice())
            .await
            .map_err(dg)
    }

    /// Record `msg` if it is a CoE emergency; returns whether it was one.
    fn collect_emergency(&mut self, msg: &[u8]) -> bool {
        let Ok((h, body)) = MailboxHeader::parse(msg) else {
            return false;
        };
        if h.mailbox_type != MailboxType::Coe {
            return false;
        }
        let Ok((coe, rest)) = CoeHeader::parse(body) else {
            return false;
        };
        if coe.service != CoeService::Emergency {
            return false;
        }
        let mut e = Emergency {
            code: 0,
            register: 0,
            data: [0; 5],
        };
        if rest.len() >= 2 {
            e.code = u16::from_le_bytes([rest[0], rest[1]]);
        }
        if let Some(r) = rest.get(2) {
            e.register = *r;
        }
        for (d, s) in e.data.iter_mut().zip(rest.iter().skip(3)) {
            *d = *s;
        }
        self.emergencies.push(e);
        true
    }

    /// Wait for the next message of protocol `mailbox_type` (SM1 full → read) and return its
    /// body (after the mailbox header, cut to the header's length). CoE emergencies are
    /// collected and skipped; a mailbox error reply (type 0) becomes
    /// [`MailboxError::MailboxErrorReply`], any other protocol a [`MailboxError::Protocol`].
    /// `what` names the awaited reply in a timeout error.
    pub async fn receive(
        &mut self,
        md: &MainDevice<'_>,
        mailbox_type: MailboxType,
        what: &'static str,
    ) -> Result<Vec<u8>, MailboxError> {
        let deadline = Instant::now() + self.timeout;
        loop {
            if Instant::now() > deadline {
                return Err(MailboxError::Timeout(self.timeout, what));
            }
            if self.sm_status(md, SM1_STATUS).await? & MBX_FULL == 0 {
                continue;
            }
            let m = self.read_mailbox(md).await?;
            if self.collect_emergency(&m) {
                continue;
            }
            let (h, body) = MailboxHeader::parse(&m)
                .map_err(|e| MailboxError::Protocol(format!("mailbox header: {e}")))?;
            if h.mailbox_type == MailboxType::Error {
                let d = body
                    .get(2..4)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]))
                    .unwrap_or(0);
                return Err(MailboxError::MailboxErrorReply(d));
            }
            if h.mailbox_type != mailbox_type {
                return Err(MailboxError::Protocol(format!(
                    "unexpected mailbox type {:?} (waiting for {mailbox_type:?})",
                    h.mailbox_type
                )));
            }
            return Ok(body.to_vec());
        }
    }
}

/// CoE (SDO) client for one SubDevice, on a [`MailboxTransport`].
#[derive(Debug)]
pub struct CoeClient {
    transport: MailboxTransport,
    /// Bound for each wait (mailbox free, response).
    pub timeout: Duration,
    /// Bound of one whole transfer, request to last segment or fragment (default
    /// [`DEFAULT_TRANSFER_TIMEOUT`]).
    pub transfer_timeout: Duration,
}

impl CoeClient {
    /// Client for the SubDevice at configured `station_address`, with the write mailbox
    /// (SM0) and read mailbox (SM1) as (start address, length).
    pub fn new(station_address: u16, mbx_out: (u16, u16), mbx_in: (u16, u16)) -> Self {
        Self::from_transport(MailboxTransport::new(station_address, mbx_out, mbx_in))
    }

    /// Client for the SubDevice at configured `station_address`, its mailbox areas read from
    /// the device ([`MailboxTransport::discover`]).
    ///
    /// # Errors
    /// As [`MailboxTransport::discover`].
    pub async fn discover(md: &MainDevice<'_>, station_address: u16) -> Result<Self, MailboxError> {
        Ok(Self::from_transport(
            MailboxTransport::discover(md, station_address).await?,
        ))
    }

    /// Client on an existing transport (e.g. shared with an SoE client); the timeout is the
    /// transport's.
    pub fn from_transport(transport: MailboxTransport) -> Self {
        Self {
            timeout: transport.timeout,
            transfer_timeout: DEFAULT_TRANSFER_TIMEOUT,
            transport,
        }
    }

    /// The transport back (with this client's timeout).
    pub fn into_transport(mut self) -> MailboxTransport {
        self.transport.timeout = self.timeout;
        self.transport
    }

    /// Emergencies received so far (drains the list).
    pub fn take_emergencies(&mut self) -> Vec<Emergency> {
        self.transport.take_emergencies()
    }

    /// The transport with this client's current timeout.
    fn tp(&mut self) -> &mut MailboxTransport {
        self.transport.timeout = self.timeout;
        &mut self.transport
    }

    async fn send(&mut self, md: &MainDevice<'_>, body: &[u8]) -> Result<(), MailboxError> {
        self.tp().send(md, MailboxType::Coe, body).await
    }

    /// Wait for the SDO response (SM1 full → read); emergencies are collected and skipped.
    /// Returns the SDO bytes (after the CoE header).
    async fn receive_sdo(&mut self, md: &MainDevice<'_>) -> Result<Vec<u8>, MailboxError> {
        let body = self
            .tp()
            .receive(md, MailboxType::Coe, "SDO response")
            .await?;
        let (coe, rest) = CoeHeader::parse(&body)
            .map_err(|e| MailboxError::Protocol(format!("CoE header: {e}")))?;
        // An abort comes as an SDO *request* (CoE service 2, command specifier 4 = 0x80;
        // ETG.1000.6 "Abort SDO Transfer Request") in both directions.
        let abort =
            coe.service == CoeService::SdoRequest && rest.first().is_some_and(|b| b & 0xE0 == 0x80);
        if coe.service != CoeService::SdoResponse && !abort {
            return Err(MailboxError::Protocol(format!(
                "unexpected CoE service {:?}",
                coe.service
            )));
        }
        Ok(rest.to_vec())
    }

    fn sdo_body(sdo: &[u8]) -> Vec<u8> {
        let mut b = CoeHeader {
            number: 0,
            service: CoeService::SdoRequest,
        }
        .encode()
        .to_vec();
        b.extend_from_slice(sdo);
        b
    }

    fn check_abort(f: &SdoFrame<'_>, index: u16, sub: u8) -> Result<(), MailboxError> {
        if f.command == SdoCommand::Abort {
            let code = f.abort_code.unwrap_or(0);
            return Err(MailboxError::Abort {
                index: f.index.unwrap_or(index),
                sub: f.subindex.unwrap_or(sub),
                code,
                text: abort_text(code),
            });
        }
        Ok(())
    }

    /// Best effort abort of a running transfer (errors ignored).
    async fn send_abort(&mut self, md: &MainDevice<'_>, index: u16, sub: u8, code: u32) {
        let mut sdo = vec![0x80];
        sdo.extend_from_slice(&index.to_le_bytes());
        sdo.push(sub);
        sdo.extend_from_slice(&code.to_le_bytes());
        let _ = self.send(md, &Self::sdo_body(&sdo)).await;
    }

    /// SDO upload (expedited, normal or segmented).
    pub async fn sdo_upload(
        &mut self,
        md: &MainDevice<'_>,
        index: u16,
        sub: u8,
    ) -> Result<Vec<u8>, MailboxError> {
        let mut sdo = vec![SdoCommand::InitiateUploadRequest {
            complete_access: false,
        }
        .encode()];
        sdo.extend_from_slice(&index.to_le_bytes());
        sdo.push(sub);
        sdo.extend_from_slice(&[0; 4]);
        self.send(md, &Self::sdo_body(&sdo)).await?;
        let r = self.receive_sdo(md).await?;
        let f = SdoFrame::parse(&r, SdoDirection::Response)
            .map_err(|e| MailboxError::Protocol(format!("SDO: {e}")))?;
        Self::check_abort(&f, index, sub)?;
        let SdoCommand::InitiateUploadResponse {
            expedited,
            size_indicated,
            unused,
            ..
        } = f.command
        else {
            return Err(MailboxError::Protocol(format!(
                "expected initiate upload response, got {:?}",
                f.command
            )));
        };
        if f.index != Some(index) || f.subindex != Some(sub) {
            return Err(MailboxError::Protocol(format!(
                "response for {:?}:{:?}",
                f.index, f.subindex
            )));
        }
        if expedited {
            let n = if size_indicated {
                4 - usize::from(unused)
            } else {
                4
            };
            return f
                .data
                .get(..n)
                .map(<[u8]>::to_vec)
                .ok_or_else(|| MailboxError::Protocol("short expedited response".into()));
        }
        if f.data.len() < 4 {
            return Err(MailboxError::Protocol("missing size".into()));
        }
        let start = Instant::now();
        let announced = u32::from_le_bytes([f.data[0], f.data[1], f.data[2], f.data[3]]) as usize;
        // Without size indication the byte cap is the bound (CiA 301 0x05040005 beyond it).
        let total = if size_indicated {
            announced
        } else {
            crate::limits::MAX_MAILBOX_OBJECT_BYTES
        };
        if total > crate::limits::MAX_MAILBOX_OBJECT_BYTES {
            self.send_abort(md, index, sub, 0x0504_0005).await;
            return Err(MailboxError::ObjectTooLarge {
                size: total,
                limit: crate::limits::MAX_MAILBOX_OBJECT_BYTES,
            });
        }
        let mut out = f.data[4..].to_vec();
        if size_indicated && out.len() >= total {
            out.truncate(total);
            return Ok(out);
        }
        // Segmented upload: bounded by the size announced (or the cap) and by
        // `transfer_timeout` (a device may answer every segment without data and end bit).
        let mut toggle = false;
        let mut segments = 0u64;
        loop {
            let after = start.elapsed();
            if after > self.transfer_timeout {
                self.send_abort(md, index, sub, 0x0504_0000).await;
                let size = if size_indicated {
                    format!("of the {total} bytes announced")
                } else {
                    "bytes, no size announced".to_string()
                };
                return Err(MailboxError::TransferTimeout {
                    what: format!("SDO {index:#06x}:{sub:02x} upload"),
                    after,
                    progress: format!(
                        "{segments} segments, {} {size}; sent abort 0x05040000, {}",
                        out.len(),
                        abort_text(0x0504_0000)
                    ),
                });
            }
            segments += 1;
            let mut seg = vec![SdoCommand::UploadSegmentRequest { toggle }.encode()];
            seg.extend_from_slice(&[0; 7]);
            self.send(md, &Self::sdo_body(&seg)).await?;
            let r = self.receive_sdo(md).await?;
            let f = SdoFrame::parse(&r, SdoDirection::Response)
                .map_err(|e| MailboxError::Protocol(format!("SDO: {e}")))?;
            Self::check_abort(&f, index, sub)?;
            let SdoCommand::UploadSegmentResponse {
                toggle: t,
                unused,
                last,
            } = f.command
            else {
                return Err(MailboxError::Protocol(format!(
                    "expected upload segment response, got {:?}",
                    f.command
                )));
            };
            if t != toggle {
                self.send_abort(md, index, sub, 0x0503_0000).await;
                return Err(MailboxError::Abort {
                    index,
                    sub,
                    code: 0x0503_0000,
                    text: abort_text(0x0503_0000),
                });
            }
            let mut data = f.data;
            if data.len() <= 7 {
                data = &data[..data.len().saturating_sub(usize::from(unused))];
            }
            if out.len() + data.len() > total && !last {
                // Never more than announced (or than the cap without a size).
                let code = if size_indicated {
                    0x0607_0012
                } else {
                    0x0504_0005
                };
                self.send_abort(md, index, sub, code).await;
                if !size_indicated {
                    return Err(MailboxError::ObjectTooLarge {
                        size: out.len() + data.len(),
                        limit: total,
                    });
                }
                return Err(MailboxError::Protocol(format!(
                    "SDO {index:#06x}:{sub:02x} upload: segment {segments} brings {} bytes after {}, {total} announced (sent abort {code:#010x}, {})",
                    data.len(),
                    out.len(),
                    abort_text(code)
                )));
            }
            out.extend_from_slice(data);
            if last || (size_indicated && out.len() >= total) {
                out.truncate(total);
                return Ok(out);
            }
            toggle = !toggle;
        }
    }

    /// SDO download (expedited ≤ 4 bytes, normal, or segmented when the data do not fit the
    /// write mailbox).
    pub async fn sdo_download(
        &mut self,
        md: &MainDevice<'_>,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<(), MailboxError> {
        let mut sdo;
        let mut rest: &[u8] = &[];
        if data.len() <= 4 {
            sdo = vec![SdoCommand::InitiateDownloadRequest {
                complete_access: false,
                expedited: true,
                size_indicated: true,
                unused: (4 - data.len()) as u8,
            }
            .encode()];
            sdo.extend_from_slice(&index.to_le_bytes());
            sdo.push(sub);
            sdo.extend_from_slice(data);
            sdo.resize(8, 0);
        } else {
            // Mailbox header 6 + CoE 2 + command/index/sub 4 + size 4.
            let cap = self.transport.write_mailbox_len().saturating_sub(16);
            if cap == 0 {
                return Err(MailboxError::TooLarge(data.len()));
            }
            let first = data.len().min(cap);
            sdo = vec![SdoCommand::InitiateDownloadRequest {
                complete_access: false,
                expedited: false,
                size_indicated: true,
                unused: 0,
            }
            .encode()];
            sdo.extend_from_slice(&index.to_le_bytes());
            sdo.push(sub);
            sdo.extend_from_slice(&(data.len() as u32).to_le_bytes());
            sdo.extend_from_slice(&data[..first]);
            rest = &data[first..];
        }
        self.send(md, &Self::sdo_body(&sdo)).await?;
        let r = self.receive_sdo(md).await?;
        let f = SdoFrame::parse(&r, SdoDirection::Response)
            .map_err(|e| MailboxError::Protocol(format!("SDO: {e}")))?;
        Self::check_abort(&f, index, sub)?;
        if f.command != SdoCommand::InitiateDownloadResponse {
            return Err(MailboxError::Protocol(format!(
                "expected initiate download response, got {:?}",
                f.command
            )));
        }
        // Segments: mailbox header 6 + CoE 2 + command 1.
        let seg_cap = self.transport.write_mailbox_len().saturating_sub(9).max(7);
        let mut toggle = false;
        while !rest.is_empty() {
            let n = rest.len().min(seg_cap);
            let last = n == rest.len();
            let unused = 7usize.saturating_sub(n) as u8;
            let mut seg = vec![SdoCommand::DownloadSegmentRequest {
                toggle,
                unused,
                last,
            }
            .encode()];
            seg.extend_from_slice(&rest[..n]);
            if seg.len() < 8 {
                seg.resize(8, 0);
            }
            self.send(md, &Self::sdo_body(&seg)).await?;
            let r = self.receive_sdo(md).await?;
            let f = SdoFrame::parse(&r, SdoDirection::Response)
                .map_err(|e| MailboxError::Protocol(format!("SDO: {e}")))?;
            Self::check_abort(&f, index, sub)?;
            match f.command {
                SdoCommand::DownloadSegmentResponse { toggle: t } if t == toggle => {}
                SdoCommand::DownloadSegmentResponse { .. } => {
                    self.send_abort(md, index, sub, 0x0503_0000).await;
                    return Err(MailboxError::Abort {
                        index,
                        sub,
                        code: 0x0503_0000,
                        text: abort_text(0x0503_0000),
                    });
                }
                other => {
                    return Err(MailboxError::Protocol(format!(
                        "expected download segment response, got {other:?}"
                    )))
                }
            }
            rest = &rest[n..];
            toggle = !toggle;
        }
        Ok(())
    }
}

/// SDO Information (ETG.1000.6 §5.6.3, CoE service 8): object list and descriptions, for
/// listing a device's dictionary (`fieldprobe sdos`). Wire layout in [`super::sdo_info`];
/// fragmented responses are reassembled with the caps of
/// [`super::sdo_info::FragmentCollector`].
impl CoeClient {
    /// Send one SDO information request and collect its (possibly fragmented) response data.
    async fn sdo_info(
        &mut self,
        md: &MainDevice<'_>,
        opcode: SdoInfoOpcode,
        data: &[u8],
        expect: SdoInfoOpcode,
        what: impl Fn() -> String,
    ) -> Result<Vec<u8>, MailboxError> {
        self.send(md, &sdo_info::request(opcode, data))
            .await
            .map_err(no_sdo_info)?;
        let mut c = sdo_info::FragmentCollector::new(expect);
        let start = Instant::now();
        let mut fragments = 0u64;
        loop {
            let after = start.elapsed();
            if after > self.transfer_timeout {
                return Err(MailboxError::TransferTimeout {
                    what: format!("SDO information {}", what()),
                    after,
                    progress: format!("{fragments} fragments"),
                });
            }
            fragments += 1;
            let body = self
                .tp()
                .receive(md, MailboxType::Coe, "SDO information response")
                .await
                .map_err(no_sdo_info)?;
            match c.push(&body) {
                Ok(Some(d)) => return Ok(d),
                Ok(None) => {}
                Err(sdo_info::SdoInfoError::Refused { code }) => {
                    return Err(MailboxError::SdoInfo {
                        what: what(),
                        code,
                        text: abort_text(code),
                    })
                }
                Err(e) => return Err(MailboxError::Protocol(format!("{}: {e}", what()))),
            }
        }
    }

    /// Get OD List of `list` ([`sdo_info::list_type`]): the object indexes (type 0: the five
    /// counts).
    pub async fn od_list(
        &mut self,
        md: &MainDevice<'_>,
        list: u16,
    ) -> Result<Vec<u16>, MailboxError> {
        let d = self
            .sdo_info(
                md,
                SdoInfoOpcode::GetOdListRequest,
                &list.to_le_bytes(),
                SdoInfoOpcode::GetOdListResponse,
                || "OD list".to_string(),
            )
            .await?;
        sdo_info::parse_od_list(list, &d)
            .map_err(|e| MailboxError::Protocol(format!("OD list: {e}")))
    }

    /// Get Object Description of `index`.
    pub async fn object_description(
        &mut self,
        md: &MainDevice<'_>,
        index: u16,
    ) -> Result<sdo_info::ObjectDescription, MailboxError> {
        let what = || format!("object {index:#06x}");
        let d = self
            .sdo_info(
                md,
                SdoInfoOpcode::GetObjectDescriptionRequest,
                &index.to_le_bytes(),
                SdoInfoOpcode::GetObjectDescriptionResponse,
                what,
            )
            .await?;
        let o = sdo_info::ObjectDescription::parse(&d)
            .map_err(|e| MailboxError::Protocol(format!("{}: {e}", what())))?;
        if o.index != index {
            return Err(MailboxError::Protocol(format!(
                "{}: the response describes object {:#06x}",
                what(),
                o.index
            )));
        }
        Ok(o)
    }

    /// Get Entry Description of `index:sub` (value info 0x07 as SOEM asks: access rights,
    /// object category, PDO mapping; no unit / default / limits).
    pub async fn entry_description(
        &mut self,
        md: &MainDevice<'_>,
        index: u16,
        sub: u8,
    ) -> Result<sdo_info::EntryDescription, MailboxError> {
        let what = || format!("entry {index:#06x}:{sub:02x}");
        let i = index.to_le_bytes();
        let d = self
            .sdo_info(
                md,
                SdoInfoOpcode::GetEntryDescriptionRequest,
                &[i[0], i[1], sub, 0x07],
                SdoInfoOpcode::GetEntryDescriptionResponse,
                what,
            )
            .await?;
        let e = sdo_info::EntryDescription::parse(&d)
            .map_err(|e| MailboxError::Protocol(format!("{}: {e}", what())))?;
        if (e.index, e.sub) != (index, sub) {
            return Err(MailboxError::Protocol(format!(
                "{}: the response describes entry {:#06x}:{:02x}",
                what(),
                e.index,
                e.sub
            )));
        }
        Ok(e)
    }
}

/// Mailbox error reply detail "unsupported protocol": the device does not speak the mailbox
/// protocol of the request (ETG.1000.4 mailbox error reply, type 0, service 1).
pub const UNSUPPORTED_PROTOCOL: u16 = 0x0002;

/// The detail code of a mailbox error reply (ETG.1000.4 mailbox error reply, type 0, service 1;
/// the codes as SOEM's `MBXERR_*` and the emulator's `sim::esc::coe::mailbox_error` name them)
/// in words.
pub fn mailbox_error_text(detail: u16) -> &'static str {
    match detail {
        0x0001 => "mailbox syntax error",
        0x0002 => "unsupported protocol",
        0x0003 => "invalid channel",
        0x0004 => "service not supported",
        0x0005 => "invalid mailbox protocol header",
        0x0006 => "received data too short",
        0x0007 => "no more memory",
        0x0008 => "inconsistent data size",
        _ => "unknown detail code",
    }
}

/// A mailbox error reply "service not supported" (0x0004) or "protocol not supported"
/// (0x0002) to an SDO information request: the device has no SDO Information service.
fn no_sdo_info(e: MailboxError) -> MailboxError {
    match e {
        MailboxError::MailboxErrorReply(d @ (0x0002 | 0x0004)) => MailboxError::NoSdoInfo(d),
        e => e,
    }
}
