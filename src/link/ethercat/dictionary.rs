//! Object dictionary and PDO configuration of a SubDevice, read over CoE by a commissioning
//! [`Session`] (`fieldprobe sdos` / `fieldprobe pdos`): the SDO Information service for the
//! dictionary (ETG.1000.6 §5.6.3), SDO uploads of the PDO assignment (0x1C12 / 0x1C13,
//! ETG.1000.6 §5.6.7.4) and mapping objects (0x1600.. / 0x1A00.., CiA 301 mapping values)
//! and the sync manager registers (ETG.1000.4 0x0800 + 8·n) for the layout.

use super::{drive, Session, EMULATED_TIMEOUT};
use crate::bus::ethercat::mailbox::{CoeClient, MailboxError};
use crate::bus::ethercat::sdo_info::{list_type, EntryDescription, ObjectCode, ObjectDescription};
use crate::link::LinkError;

/// The dictionary a device describes over SDO Information, and what it failed to describe.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Dictionary {
    /// The objects described, in the order of the OD list.
    pub objects: Vec<DictionaryObject>,
    /// The objects and entries whose description came back as an error or malformed; the
    /// listing went on with the next one.
    pub failed: Vec<DictionaryFailure>,
}

/// An object (`sub` `None`) or entry of the OD list the device did not describe.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DictionaryFailure {
    /// Object index.
    pub index: u16,
    /// Sub-index of an entry; `None`: the object's own description.
    pub sub: Option<u8>,
    /// What came back.
    pub error: String,
}

/// The device answered, wrongly or with an error, so the mailbox is still in step and the
/// listing can go on; a timeout or a lost datagram ends it (the device may be gone, and each
/// further request would wait as long).
fn answered(e: &MailboxError) -> bool {
    matches!(
        e,
        MailboxError::SdoInfo { .. }
            | MailboxError::Protocol(_)
            | MailboxError::Abort { .. }
            | MailboxError::MailboxErrorReply(_)
    )
}

/// One object of a device's dictionary: its description and the descriptions of its entries
/// (sub-indices the device refuses to describe are left out).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DictionaryObject {
    /// Object description.
    pub object: ObjectDescription,
    /// Entry descriptions, by sub-index.
    pub entries: Vec<EntryDescription>,
}

/// A sync manager as its registers show it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncManagerInfo {
    /// Number (0 …).
    pub index: u8,
    /// Physical start address (register 0x0800 + 8·n).
    pub start: u16,
    /// Length in bytes (0x0802 + 8·n).
    pub length: u16,
    /// Control register (0x0804 + 8·n).
    pub control: u8,
    /// Enabled (activate register 0x0806 + 8·n, bit 0).
    pub enable: bool,
    /// Communication type from 0x1C00 (1 mailbox out, 2 mailbox in, 3 outputs, 4 inputs, 0
    /// unused), if the device has 0x1C00.
    pub comm_type: Option<u8>,
}

/// One mapped entry of a PDO.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PdoEntryInfo {
    /// Object index (0 = gap).
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Bit length.
    pub bits: u8,
    /// Name from the SDO information service (empty without it).
    pub name: String,
}

/// One assigned PDO.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PdoInfo {
    /// Sync manager the PDO is assigned to.
    pub sm: u8,
    /// RxPDO (outputs, master → device) or TxPDO.
    pub rx: bool,
    /// PDO (mapping object) index.
    pub index: u16,
    /// Name from the SDO information service (empty without it).
    pub name: String,
    /// Mapped entries.
    pub entries: Vec<PdoEntryInfo>,
}

/// Most sync managers shown (ETG.1000.4 allows 16; the registers of 8 are read).
const MAX_SM: usize = 8;
/// Most SII bytes read for the sync manager category (a 4 KiB image, 32 kbit EEPROM, is
/// larger than any category list needs; the read stops at the End category).
const MAX_SII_BYTES: usize = 4096;

/// Read the SII EEPROM through the ESC's EEPROM interface (ETG.1000.4 registers 0x0502 control
/// / status, 0x0504 address, 0x0508 data; 4 bytes per read), from word 0 until the End
/// category (0xFFFF) or [`MAX_SII_BYTES`]. Each read waits for the busy bit (0x0502 bit 15)
/// a bounded number of polls.
async fn read_sii(md: &ethercrab::MainDevice<'_>, address: u16) -> Result<Vec<u8>, MailboxError> {
    let dg = |e: ethercrab::error::Error| MailboxError::Datagram(e.to_string());
    let mut image = Vec::new();
    let mut word = 0u32;
    // Header (64 words), then categories: type word, length word (words), data.
    let mut next_category = Some(0x40u32);
    while image.len() < MAX_SII_BYTES {
        let a = word.to_le_bytes();
        ethercrab::Command::fpwr(address, 0x0502)
            .send(md, [0x00u8, 0x01, a[0], a[1], a[2], a[3]])
            .await
            .map_err(dg)?;
        let mut done = false;
        for _ in 0..1000 {
            let st = ethercrab::Command::fprd(address, 0x0502)
                .receive::<u16>(md)
                .await
                .map_err(dg)?;
            if st & 0x8000 == 0 {
                done = true;
                break;
            }
        }
        if !done {
            return Err(MailboxError::Protocol(
                "SII read: EEPROM interface stays busy".into(),
            ));
        }
        let d = ethercrab::Command::fprd(address, 0x0508)
            .receive::<[u8; 4]>(md)
            .await
            .map_err(dg)?;
        image.extend_from_slice(&d);
        word += 2;
        // Walk the category headers: stop after the End category.
        while let Some(c) = next_category {
            let at = 2 * c as usize;
            let Some(h) = image.get(at..at + 4) else {
                break;
            };
            let ty = u16::from_le_bytes([h[0], h[1]]);
            if ty == 0xFFFF {
                return Ok(image);
            }
            let len = u32::from(u16::from_le_bytes([h[2], h[3]]));
            next_category = Some(c + 2 + len);
        }
    }
    Ok(image)
}

impl Session {
    fn coe(&self, position: usize) -> Result<CoeClient, LinkError> {
        let d = self.device(position)?;
        let mut c = CoeClient::new(d.address, d.mailbox.0, d.mailbox.1);
        if self.wire.is_emulated() {
            c.timeout = EMULATED_TIMEOUT;
        }
        Ok(c)
    }

    /// The dictionary of the SubDevice at `position` through SDO Information: Get OD List
    /// (all objects), then each object's description and its entries' descriptions
    /// (sub-index 0 … the object's highest). An entry the device refuses (SDO Info Error) is
    /// left out. An object or entry whose description comes back as an error or malformed is
    /// named in [`Dictionary::failed`] and the listing goes on; a device without the service
    /// ([`MailboxError::NoSdoInfo`]), a failed OD list, a timeout or a lost frame end it with
    /// the error.
    pub fn sdo_dictionary(&mut self, position: usize) -> Result<Dictionary, LinkError> {
        let mut c = self.coe(position)?;
        let md = self.md;
        let r = drive(&mut self.wire, async {
            let list = c.od_list(md, list_type::ALL).await?;
            let mut out = Dictionary {
                objects: Vec::with_capacity(list.len()),
                failed: Vec::new(),
            };
            for index in list {
                let object = match c.object_description(md, index).await {
                    Ok(o) => o,
                    Err(e) if answered(&e) => {
                        out.failed.push(DictionaryFailure {
                            index,
                            sub: None,
                            error: e.to_string(),
                        });
                        continue;
                    }
                    Err(e) => return Err(e),
                };
                let last = match object.object_code {
                    ObjectCode::Var => 0,
                    _ => object.max_sub,
                };
                let mut entries = Vec::new();
                for sub in 0..=last {
                    match c.entry_description(md, index, sub).await {
                        Ok(e) => entries.push(e),
                        // A sub-index the device does not describe (a RECORD with gaps).
                        Err(MailboxError::SdoInfo { .. }) => {}
                        Err(e) if answered(&e) => out.failed.push(DictionaryFailure {
                            index,
                            sub: Some(sub),
                            error: e.to_string(),
                        }),
                        Err(e) => return Err(e),
                    }
                }
                out.objects.push(DictionaryObject { object, entries });
            }
            Ok::<_, MailboxError>(out)
        });
        r.map_err(|e| self.named(position, e))
    }

    /// The sync managers and the assigned PDOs with their mapping, read from the SubDevice at
    /// `position`: the sync managers of its SII (start, default size, control byte, enable;
    /// as IgH's `ethercat pdos` shows them), else registers 0x0800.. of 8 sync
    /// managers (those with a start address or a length are kept), 0x1C00 for their types (SM2 outputs / SM3 inputs when the device
    /// lacks it), 0x1C10 + n for the PDOs of each process-data sync manager, each PDO's
    /// mapping object, and the names from SDO Information when the device offers it.
    pub fn pdo_configuration(
        &mut self,
        position: usize,
    ) -> Result<(Vec<SyncManagerInfo>, Vec<PdoInfo>), LinkError> {
        let mut c = self.coe(position)?;
        let address = self.device(position)?.address;
        let md = self.md;
        let r = drive(&mut self.wire, async {
            let regs = ethercrab::Command::fprd(address, 0x0800)
                .receive::<[u8; 8 * MAX_SM]>(md)
                .await
                .map_err(|e| MailboxError::Datagram(e.to_string()))?;
            let types = match c.sdo_upload(md, 0x1C00, 0).await {
                Ok(n) => {
                    let n = n.first().copied().unwrap_or(0).min(MAX_SM as u8);
                    let mut t = Vec::new();
                    for k in 1..=n {
                        let v = c.sdo_upload(md, 0x1C00, k).await?;
                        t.push(v.first().copied().unwrap_or(0));
                    }
                    Some(t)
                }
                Err(MailboxError::Abort { .. }) => None,
                Err(e) => return Err(e),
            };
            // The SII's sync manager category (what the device declares, as IgH shows it);
            // the registers where the SII has none.
            let sii_sms: Vec<crate::esi::sii::SyncManager> = match read_sii(md, address).await {
                Ok(img) => crate::esi::sii::decode_ignoring_checksum(&img)
                    .map(|c| c.sync_managers().to_vec())
                    .unwrap_or_default(),
                Err(_) => Vec::new(),
            };
            let mut sms = Vec::new();
            for n in 0..MAX_SM {
                let r = &regs[8 * n..8 * n + 8];
                let sm = match sii_sms.get(n) {
                    Some(s) => SyncManagerInfo {
                        index: n as u8,
                        start: s.start,
                        length: s.length,
                        control: s.control,
                        enable: s.enable & 0x01 != 0,
                        comm_type: types.as_ref().and_then(|t| t.get(n).copied()),
                    },
                    None => SyncManagerInfo {
                        index: n as u8,
                        start: u16::from_le_bytes([r[0], r[1]]),
                        length: u16::from_le_bytes([r[2], r[3]]),
                        control: r[4],
                        enable: r[6] & 0x01 != 0,
                        comm_type: types.as_ref().and_then(|t| t.get(n).copied()),
                    },
                };
                let listed = types.as_ref().is_some_and(|t| n < t.len());
                if sm.start != 0 || sm.length != 0 || listed {
                    sms.push(sm);
                }
            }
            let mut names = true;
            let mut pdos = Vec::new();
            for sm in &sms {
                let ty = sm.comm_type.unwrap_or(match sm.index {
                    2 => 3,
                    3 => 4,
                    _ => 0,
                });
                if ty != 3 && ty != 4 {
                    continue;
                }
                let assign = 0x1C10 + u16::from(sm.index);
                let count = match c.sdo_upload(md, assign, 0).await {
                    Ok(v) => v.first().copied().unwrap_or(0),
                    Err(MailboxError::Abort { .. }) => continue,
                    Err(e) => return Err(e),
                };
                for k in 1..=count {
                    let v = c.sdo_upload(md, assign, k).await?;
                    let index = u16::from_le_bytes([
                        v.first().copied().unwrap_or(0),
                        v.get(1).copied().unwrap_or(0),
                    ]);
                    let n = c.sdo_upload(md, index, 0).await?;
                    let mut entries = Vec::new();
                    for j in 1..=n.first().copied().unwrap_or(0) {
                        let m = c.sdo_upload(md, index, j).await?;
                        let mut w = [0u8; 4];
                        for (d, s) in w.iter_mut().zip(&m) {
                            *d = *s;
                        }
                        let m = u32::from_le_bytes(w);
                        entries.push(PdoEntryInfo {
                            index: (m >> 16) as u16,
                            sub: (m >> 8) as u8,
                            bits: m as u8,
                            name: String::new(),
                        });
                    }
                    let mut name = String::new();
                    if names {
                        match c.object_description(md, index).await {
                            Ok(o) => name = o.name,
                            Err(MailboxError::NoSdoInfo(_)) => names = false,
                            Err(MailboxError::SdoInfo { .. }) => {}
                            Err(e) => return Err(e),
                        }
                    }
                    if names {
                        for e in entries.iter_mut().filter(|e| e.index != 0) {
                            match c.entry_description(md, e.index, e.sub).await {
                                Ok(d) => e.name = d.name,
                                Err(MailboxError::SdoInfo { .. }) => {}
                                Err(err) => return Err(err),
                            }
                        }
                    }
                    pdos.push(PdoInfo {
                        sm: sm.index,
                        rx: ty == 3,
                        index,
                        name,
                        entries,
                    });
                }
            }
            Ok::<_, MailboxError>((sms, pdos))
        });
        r.map_err(|e| self.named(position, e))
    }
}

#[cfg(all(test, feature = "sim"))]
mod tests {
    use super::super::{EthercatSpec, Wire};
    use super::*;
    use crate::sim::esc::sdo_info::DescriptionFault;

    #[test]
    fn one_object_the_device_cannot_describe_does_not_end_the_listing() {
        // Issue 26: `sdos` aborted the whole listing on one bad SDO Information reply.
        let spec = EthercatSpec {
            drives: vec![std::sync::Arc::new(
                crate::drive::catalogue::load("cia402-generic").expect("built-in drive"),
            )],
            ..EthercatSpec::default()
        };
        let mut s = Session::open(&Wire::Emulated, &spec).expect("emulated segment");
        let position = 1; // coupler, servo
        let whole = s.sdo_dictionary(position).expect("dictionary");
        assert!(whole.failed.is_empty(), "{:?}", whole.failed);
        let listed: Vec<u16> = whole.objects.iter().map(|o| o.object.index).collect();
        assert!(
            listed.contains(&0x6040) && listed.contains(&0x1018),
            "{listed:x?}"
        );
        let coe = s
            .wire
            .segment_mut()
            .and_then(|seg| seg.esc_mut(position))
            .and_then(|esc| esc.app_mut().coe_mut())
            .expect("the servo's CoE server");
        let mut d = coe.descriptions().clone();
        // One object refused though listed, one answered with another object's description.
        d.set_fault(0x6040, DescriptionFault::Refused(0x0800_0000));
        d.set_fault(0x1018, DescriptionFault::OtherObject(0x1000));
        coe.set_descriptions(d);
        let broken = s.sdo_dictionary(position).expect("listing goes on");
        let failed: Vec<(u16, Option<u8>)> =
            broken.failed.iter().map(|f| (f.index, f.sub)).collect();
        assert_eq!(
            failed,
            vec![(0x1018, None), (0x6040, None)],
            "{:?}",
            broken.failed
        );
        assert!(
            broken.failed[0].error.contains("describes object 0x1000"),
            "{:?}",
            broken.failed
        );
        assert!(
            broken.failed[1].error.contains("0x08000000"),
            "{:?}",
            broken.failed
        );
        // Every other object exactly as before.
        let rest: Vec<&DictionaryObject> = whole
            .objects
            .iter()
            .filter(|o| ![0x6040, 0x1018].contains(&o.object.index))
            .collect();
        assert_eq!(broken.objects.iter().collect::<Vec<_>>(), rest);
    }
}
