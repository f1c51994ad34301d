//! The PDO mapping the master writes in PRE-OP, fitted to what the device offers.
//!
//! Before the mapping of an axis's drive definition (`drives/*.toml` `[rxpdo]` / `[txpdo]`)
//! is written, every entry is checked against the device's object dictionary: the SDO
//! Information service's entry description (ETG.1000.6 §5.6.3.6: the object exists, it is
//! mappable into an RxPDO resp. a TxPDO — object access bits 6 / 7 — and has the bit length
//! the drive file maps); a device without that service (mailbox error "service not
//! supported") is asked with an SDO upload whether the object exists, and the mapping writes
//! themselves then refuse what cannot be mapped (0x0604_0041).
//!
//! * A **required** object the device lacks (anything but the touch probe) refuses the
//!   start-up: error [`ids::ETHERCAT_PDO_OBJECTS_MISSING`] names the objects, why each one
//!   does not fit, the device and the drive.
//! * The **touch-probe** objects (0x60B8–0x60BD, 0x60D0, 0x60D5–0x60D8) are optional: when the
//!   device lacks one of them, they are left out of the mapping (all of them when 0x60B8 or
//!   0x60B9 is missing: the latch needs both), the axis runs with that reduced definition and
//!   so has no drive latch, and warning [`ids::ETHERCAT_NO_DRIVE_LATCH`] says so. Many real
//!   CiA 402 drives have no touch probe (issue 19; seed 004 §7 lists what measures without
//!   one: PLC sampling, PLC_TIMESTAMP with a timestamp input terminal, an external latch).

use std::sync::Arc;

use ethercrab::MainDevice;

use crate::bus::ethercat::mailbox::{CoeClient, MailboxError};
use crate::bus::ethercat::sdo_info::access;
use crate::drive::catalogue::DriveDefinition;
use crate::drive::pdo::PdoLayout;
use crate::link::LinkError;
use crate::messages::{ids, CncMessage};

/// The mapping to write for one axis.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The drive definition whose `[rxpdo]` / `[txpdo]` the device gets (the axis's own when
    /// nothing was left out).
    pub def: Arc<DriveDefinition>,
    /// Warning [`ids::ETHERCAT_NO_DRIVE_LATCH`] when touch-probe objects were left out.
    pub warning: Option<CncMessage>,
}

/// Is `index` one of the optional touch-probe objects (CiA 402 0x60B8–0x60BD, 0x60D0,
/// 0x60D5–0x60D8)?
pub fn is_touch_probe(index: u16) -> bool {
    matches!(index, 0x60B8..=0x60BD | 0x60D0 | 0x60D5..=0x60D8)
}

/// Does the device offer `index:sub` with `bits` bits for an RxPDO (`rx`) or a TxPDO? `Ok(None)`
/// yes, `Ok(Some(why not))`; `Err` when the device could not be asked. `sdo_info` turns off
/// once the device says it has no SDO Information service.
async fn offered(
    md: &MainDevice<'_>,
    c: &mut CoeClient,
    (index, sub, bits): (u16, u8, u32),
    rx: bool,
    sdo_info: &mut bool,
    who: &str,
) -> Result<Option<String>, LinkError> {
    let absent = |code: u32| code == 0x0602_0000 || code == 0x0609_0011;
    let failed = |e: MailboxError| {
        LinkError::Other(format!(
            "device {who}: asking for object {index:#06x}:{sub:02x}: {e}"
        ))
    };
    if *sdo_info {
        match c.entry_description(md, index, sub).await {
            Ok(d) => {
                let (flag, what) = if rx {
                    (access::RXPDO, "an RxPDO")
                } else {
                    (access::TXPDO, "a TxPDO")
                };
                if d.access & flag == 0 {
                    return Ok(Some(format!("not mappable into {what}")));
                }
                if u32::from(d.bit_len) != bits {
                    return Ok(Some(format!(
                        "{} bits on the device, {bits} in the drive file",
                        d.bit_len
                    )));
                }
                return Ok(None);
            }
            Err(MailboxError::SdoInfo { code, .. }) if absent(code) => {
                return Ok(Some("not in its object dictionary".into()))
            }
            Err(MailboxError::NoSdoInfo(_)) => *sdo_info = false,
            Err(e) => return Err(failed(e)),
        }
    }
    match c.sdo_upload(md, index, sub).await {
        Ok(_) => Ok(None),
        Err(MailboxError::Abort { code, .. }) if absent(code) => {
            Ok(Some("not in its object dictionary".into()))
        }
        // Exists (e.g. write-only); whether it maps, the mapping write says.
        Err(MailboxError::Abort { .. }) => Ok(None),
        Err(e) => Err(failed(e)),
    }
}

/// Fit the mapping of `def` to the device behind `c` (see the module documentation); `who`
/// names the axis and device in messages.
pub async fn fit_mapping(
    md: &MainDevice<'_>,
    c: &mut CoeClient,
    def: &Arc<DriveDefinition>,
    who: &str,
) -> Result<Fitted, LinkError> {
    let mut sdo_info = true;
    let mut lacking = Vec::new();
    let mut missing_probe: Vec<(u16, u8, String)> = Vec::new();
    for (layout, rx, fixed) in [
        (&def.rxpdo, true, def.rx_assign.fixed),
        (&def.txpdo, false, def.tx_assign.fixed),
    ] {
        // A fixed PDO is the device's own mapping: read back and compared when assigned.
        if fixed {
            continue;
        }
        for e in layout.entries().iter().filter(|e| !e.is_gap()) {
            let bits = u32::from(e.bits);
            let Some(why) = offered(md, c, (e.index, e.sub, bits), rx, &mut sdo_info, who).await?
            else {
                continue;
            };
            if is_touch_probe(e.index) {
                missing_probe.push((e.index, e.sub, why));
            } else {
                lacking.push(format!("{:#06X}:{:02X} ({why})", e.index, e.sub));
            }
        }
    }
    if !lacking.is_empty() {
        return Err(LinkError::Refused(CncMessage::error(
            ids::ETHERCAT_PDO_OBJECTS_MISSING,
            format!(
                "device {who}: drive '{}' ({}) maps objects the device does not offer: {}",
                def.name,
                def.file,
                lacking.join(", ")
            ),
        )));
    }
    if missing_probe.is_empty() {
        return Ok(Fitted {
            def: def.clone(),
            warning: None,
        });
    }
    let latch_gone = missing_probe
        .iter()
        .any(|(i, _, _)| *i == 0x60B8 || *i == 0x60B9);
    let drop = |index: u16, sub: u8| {
        (latch_gone && is_touch_probe(index))
            || missing_probe
                .iter()
                .any(|(i, s, _)| (*i, *s) == (index, sub))
    };
    let cut = |layout: &PdoLayout| -> Result<PdoLayout, LinkError> {
        let kept: Vec<_> = layout
            .entries()
            .iter()
            .filter(|e| e.is_gap() || !drop(e.index, e.sub))
            .map(|e| e.spec())
            .collect();
        PdoLayout::from_specs(&kept)
            .and_then(|l| l.with_roles(&def.roles))
            .map_err(|e| LinkError::Other(e.to_string()))
    };
    let mut fitted = (**def).clone();
    fitted.rxpdo = cut(&def.rxpdo)?;
    fitted.txpdo = cut(&def.txpdo)?;
    fitted.rxpdo_defaults.retain(|d| !drop(d.index, d.sub));
    // "0x60B8:00, 0x60B9:00 (not in its object dictionary)": objects grouped by reason.
    let mut listed: Vec<String> = Vec::new();
    let mut reasons: Vec<&str> = missing_probe.iter().map(|(_, _, w)| w.as_str()).collect();
    reasons.dedup();
    for why in reasons {
        let objects: Vec<String> = missing_probe
            .iter()
            .filter(|(_, _, w)| w == why)
            .map(|(i, s, _)| format!("{i:#06X}:{s:02X}"))
            .collect();
        listed.push(format!("{} ({why})", objects.join(", ")));
    }
    let text = if latch_gone {
        format!(
            "device {who} has no touch probe for drive '{}': {}; the PDO mapping leaves the \
             touch-probe objects out and the axis has no drive latch (measure with PLC, \
             PLC_TIMESTAMP and a timestamp input terminal, or an external latch, seed 004 §7)",
            def.name,
            listed.join(", ")
        )
    } else {
        format!(
            "device {who} lacks touch-probe objects of drive '{}': {}; the PDO mapping leaves \
             them out",
            def.name,
            listed.join(", ")
        )
    };
    Ok(Fitted {
        def: Arc::new(fitted),
        warning: Some(CncMessage::warning(ids::ETHERCAT_NO_DRIVE_LATCH, text)),
    })
}

/// The device type (CoE 0x1000, CiA 301 §7.5.2.1) of each SubDevice at `stations` that is not
/// `servo` (fieldprobe's own emulated servo, which is matched by identity): `Some(value)` when
/// it has a CoE mailbox and answers (0 when it refuses the upload), `None` without a mailbox
/// or an answer. The CoE clients used, per station (the link goes on with them: a new client
/// would start the mailbox counter again, which the device takes for a repeated request).
pub async fn device_types(
    md: &MainDevice<'_>,
    stations: &[u16],
    ids: &[(u32, u32)],
    servo: (u32, u32),
) -> (Vec<Option<u32>>, Vec<Option<CoeClient>>) {
    let mut types = Vec::new();
    let mut clients = Vec::new();
    for (id, &station) in ids.iter().zip(stations) {
        if *id == servo {
            types.push(None);
            clients.push(None);
            continue;
        }
        let Ok(mut c) = CoeClient::discover(md, station).await else {
            types.push(None);
            clients.push(None);
            continue;
        };
        let t = match c.sdo_upload(md, 0x1000, 0).await {
            Ok(v) => {
                let mut b = [0u8; 4];
                let n = v.len().min(4);
                b[..n].copy_from_slice(&v[..n]);
                Some(u32::from_le_bytes(b))
            }
            Err(MailboxError::Abort { .. }) => Some(0),
            Err(_) => None,
        };
        types.push(t);
        clients.push(Some(c));
    }
    (types, clients)
}

/// Check the device type (0x1000) of a CiA 402 axis's device: CiA 402 says 402 in the low
/// word (0x0192); a Beckhoff modular-device-profile terminal says 5001 (0x1389). Anything
/// else — or no answer — is warning [`ids::ETHERCAT_DEVICE_CHECK`], not a refusal: vendor
/// files and firmware write many values there (the device is taken by its identity and
/// position).
pub async fn check_device_type(
    md: &MainDevice<'_>,
    c: &mut CoeClient,
    def: &DriveDefinition,
    who: &str,
) -> Option<CncMessage> {
    if def.profile != crate::drive::catalogue::Profile::Cia402 {
        return None;
    }
    let said = match c.sdo_upload(md, 0x1000, 0).await {
        Ok(v) => {
            let mut b = [0u8; 4];
            let n = v.len().min(4);
            b[..n].copy_from_slice(&v[..n]);
            let t = u32::from_le_bytes(b);
            if matches!(t & 0xFFFF, 402 | 5001) {
                return None;
            }
            format!("reports device type {t:#010x}")
        }
        Err(e) => format!("does not give its device type 0x1000 ({e})"),
    };
    Some(CncMessage::warning(
        ids::ETHERCAT_DEVICE_CHECK,
        format!(
            "device {who} {said}; a CiA 402 drive says 402 (0x0192) in the low word: taken as \
             drive '{}' all the same",
            def.name
        ),
    ))
}
