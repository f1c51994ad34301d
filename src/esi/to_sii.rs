//! ESI device description → SII EEPROM content (ETG.2010), ready for [`super::sii::encode`].
//!
//! [`sii_from_device`] fills the fixed header (ConfigData words, identity with serial 0,
//! bootstrap and standard mailbox from `Eeprom/BootStrap` and the `MBoxOut` / `MBoxIn` sync
//! managers, mailbox protocols, EEPROM size) and the categories Strings, General, FMMU,
//! SyncManager, TxPDO, RxPDO and DC (the last three only when the device has any).
//!
//! Choices where ETG.2000 and ETG.2010 do not map one to one:
//! * Strings are stored as Latin-1: other characters become `?`, texts longer than 255 bytes
//!   are cut. When the table is full (255 strings) further names get index 0 ("no string").
//! * General: group = `GroupType`, order = `Type` text, name = [`Device::name`], no image;
//!   CoE details get the SDO bit whenever `Mailbox/CoE` is present; an SoE device has 1 SoE
//!   channel, a device that states profile 402 anywhere ([`Device::is_cia402`]) 1 DS402
//!   channel; the only flag set is the mailbox data link layer. Physical ports follow the
//!   `Physics` letters (`Y` MII, `E` EBUS; `EBUS` = two EBUS ports).
//! * A PDO with no default sync manager gets 0xFF; PDO flags are mandatory (bit 0), default
//!   (bit 1, assigned by default) and fixed content (bit 4).
//! * An odd number of FMMUs is padded with one unused FMMU (0x00) to a whole word.
//! * `ByteSize` absent → 2048 bytes (16 KiBit).
//! * **An image larger than the ESI's EEPROM** (`Beckhoff-EJ7211-EJ7047.xml`: 2862 bytes of
//!   strings, PDOs and DC modes against `ByteSize` 2048): the header's EEPROM-size word (0x3E)
//!   declares the next size a real serial EEPROM has (powers of two from 1 KiBit; 2862 bytes →
//!   32 KiBit = 4096 bytes) and [`sii_from_device_noted`] says so in a note. The categories stay
//!   in the order and form above, so a master reads identity, strings, General, FMMUs, sync
//!   managers, PDOs and DC as from any image: ethercrab and SOEM walk the category chain and do
//!   not stop at the declared size (SOEM's SII cache holds 4096 bytes, enough for such an
//!   image). An emulated ESC with more than 2048 bytes reports two address bytes (register
//!   0x0502 bit 7), as an ESC with a 32 KiBit EEPROM does. Devices with such ESIs exist: their
//!   makers fit the data, a configurator writing the ESI's categories needs the larger part.
//!   Larger than 4 MiBit (the largest two-address-byte EEPROM) stays an error.

use super::sii::{self, Category, General, MailboxLayout, SiiContent, SiiError, SiiHeader};
use super::{Device, EsiFile, FmmuKind, SmKind};

/// EEPROM size used when the ESI gives no `Eeprom/ByteSize`.
pub const DEFAULT_EEPROM_BYTES: u32 = 2048;

/// Largest EEPROM the header may declare for a grown image: 4 MiBit (512 KiB).
const MAX_EEPROM_BYTES: usize = 512 * 1024;

/// [`sii_from_device_noted`]'s result: the content and what the caller should know about it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SiiBuild {
    /// The SII content.
    pub content: SiiContent,
    /// Notes (an EEPROM declared larger than the ESI's `ByteSize`, see the module docs).
    pub notes: Vec<String>,
}

/// Build the SII EEPROM content of `device` (one of `file.devices`, or a device resolved from
/// it; the vendor ID comes from `file.vendor`). Fails on values the SII cannot hold (a PDO
/// entry longer than 255 bits, a DC factor outside `i16`, a DC time outside 32 bits, an EEPROM
/// larger than 8 MiBit). An image that does not fit the ESI's EEPROM gets a larger one (module
/// docs); [`sii_from_device_noted`] returns the note that says so.
pub fn sii_from_device(file: &EsiFile, device: &Device) -> Result<SiiContent, SiiError> {
    sii_from_device_noted(file, device).map(|b| b.content)
}

/// [`sii_from_device`] with its notes.
pub fn sii_from_device_noted(file: &EsiFile, device: &Device) -> Result<SiiBuild, SiiError> {
    let mut content = build(file, device)?;
    let mut notes = Vec::new();
    let needed = sii::encode(&content)?.len();
    let declared = content.header.eeprom_size_bytes();
    if needed > declared {
        let size = needed.next_power_of_two().max(128);
        if size > MAX_EEPROM_BYTES {
            return Err(SiiError::Encode(format!(
                "image needs {needed} bytes, more than the largest EEPROM ({MAX_EEPROM_BYTES} \
                 bytes, 4 MiBit)"
            )));
        }
        content.header.eeprom_size = (size / 128 - 1) as u16;
        notes.push(format!(
            "device {}: the SII image needs {needed} bytes, more than the {declared}-byte EEPROM \
             the ESI declares (Eeprom/ByteSize); the image declares a {size}-byte ({} KiBit) \
             EEPROM, the next size a real EEPROM has",
            device.type_name,
            size / 128
        ));
    }
    Ok(SiiBuild { content, notes })
}

fn build(file: &EsiFile, device: &Device) -> Result<SiiContent, SiiError> {
    let mut c = SiiContent {
        header: header(file, device)?,
        categories: vec![Category::Strings(Vec::new())],
    };

    // General
    let order_idx = add(&mut c, &device.type_name);
    let name_idx = add(&mut c, device.name());
    let group_idx = add(&mut c, device.group.as_deref().unwrap_or(""));
    let mut general = General {
        group_idx,
        order_idx,
        name_idx,
        group_idx2: group_idx,
        physical_ports: physical_ports(device.physics.as_deref().unwrap_or("")),
        ..General::default()
    };
    if let Some(mb) = &device.mailbox {
        if let Some(coe) = &mb.coe {
            use sii::coe_details as d;
            let mut bits = d::SDO;
            for (on, bit) in [
                (coe.sdo_info, d::SDO_INFO),
                (coe.pdo_assign, d::PDO_ASSIGN),
                (coe.pdo_config, d::PDO_CONFIG),
                (coe.pdo_upload, d::UPLOAD_AT_STARTUP),
                (coe.complete_access, d::COMPLETE_ACCESS),
            ] {
                if on {
                    bits |= bit;
                }
            }
            general.coe_details = bits;
        }
        general.foe_details = u8::from(mb.foe);
        general.eoe_details = u8::from(mb.eoe);
        general.soe_channels = u8::from(mb.soe);
        if mb.data_link_layer {
            general.flags |= sii::general_flags::MBOX_DLL;
        }
    }
    if device.is_cia402() {
        general.ds402_channels = 1;
    }
    c.categories.push(Category::General(general));

    // FMMU
    if !device.fmmus.is_empty() {
        let mut usage: Vec<u8> = device
            .fmmus
            .iter()
            .map(|f| match f {
                FmmuKind::Outputs => sii::fmmu_usage::OUTPUTS,
                FmmuKind::Inputs => sii::fmmu_usage::INPUTS,
                FmmuKind::MBoxState => sii::fmmu_usage::SM_STATUS,
                FmmuKind::Other(_) => sii::fmmu_usage::UNUSED,
            })
            .collect();
        if usage.len() % 2 == 1 {
            // the category is whole words; an explicit unused pad decodes back the same
            usage.push(sii::fmmu_usage::UNUSED);
        }
        c.categories.push(Category::Fmmu(usage));
    }

    // SyncManager
    if !device.sync_managers.is_empty() {
        let sms = device
            .sync_managers
            .iter()
            .map(|sm| sii::SyncManager {
                start: sm.start_address,
                length: sm.default_size.unwrap_or(0),
                control: sm.control_byte,
                status: 0,
                enable: if sm.enable { sii::sm_enable::ENABLE } else { 0 },
                sm_type: sm_type(&sm.kind),
            })
            .collect();
        c.categories.push(Category::SyncManagers(sms));
    }

    // PDOs
    let tx = pdos(&mut c, &device.tx_pdos)?;
    if !tx.is_empty() {
        c.categories.push(Category::TxPdos(tx));
    }
    let rx = pdos(&mut c, &device.rx_pdos)?;
    if !rx.is_empty() {
        c.categories.push(Category::RxPdos(rx));
    }

    // DC
    let mut modes = Vec::new();
    for m in &device.dc_op_modes {
        let name_idx = add(&mut c, &m.name);
        let desc_idx = add(&mut c, m.desc.as_deref().unwrap_or(""));
        let what = |t: &str| format!("DC op mode {}: {t}", m.name);
        modes.push(sii::DcOpMode {
            cycle_time_0: time(m.cycle_time_sync0.map(|t| t.value), &what("CycleTimeSync0"))?,
            shift_time_0: time(m.shift_time_sync0.map(|t| t.value), &what("ShiftTimeSync0"))?,
            shift_time_1: time(m.shift_time_sync1.map(|t| t.value), &what("ShiftTimeSync1"))?,
            sync1_cycle_factor: factor(
                m.cycle_time_sync1.and_then(|t| t.factor),
                &what("CycleTimeSync1 Factor"),
            )?,
            assign_activate: m.assign_activate,
            sync0_cycle_factor: factor(
                m.cycle_time_sync0.and_then(|t| t.factor),
                &what("CycleTimeSync0 Factor"),
            )?,
            name_idx,
            desc_idx,
            reserved: [0; 4],
        });
    }
    if !modes.is_empty() {
        c.categories.push(Category::Dc(modes));
    }

    c.check_defined_bits()?;
    Ok(c)
}

/// The fixed header.
fn header(file: &EsiFile, device: &Device) -> Result<SiiHeader, SiiError> {
    let mut h = SiiHeader {
        vendor_id: file.vendor.id,
        product_code: device.product_code,
        revision: device.revision_no,
        serial: 0,
        ..SiiHeader::default()
    };
    let eeprom = device.eeprom.as_ref();
    if let Some(cfg) = eeprom.and_then(|e| e.config_data.as_deref()) {
        // ConfigData = SII words 0..7 (the checksum word 7 is always computed by encode)
        let mut b = [0u8; 14];
        let n = cfg.len().min(14);
        b[..n].copy_from_slice(&cfg[..n]);
        let w = |i: usize| u16::from_le_bytes([b[2 * i], b[2 * i + 1]]);
        h.pdi_control = w(0);
        h.pdi_config = w(1);
        h.sync_impulse_len = w(2);
        h.pdi_config2 = w(3);
        h.station_alias = w(4);
        h.reserved_05.copy_from_slice(&b[10..14]);
    }
    if let Some(bs) = eeprom.and_then(|e| e.boot_strap.as_deref()) {
        let mut b = [0u8; 8];
        let n = bs.len().min(8);
        b[..n].copy_from_slice(&bs[..n]);
        let w = |i: usize| u16::from_le_bytes([b[2 * i], b[2 * i + 1]]);
        h.bootstrap_mailbox = MailboxLayout {
            rx_offset: w(0),
            rx_size: w(1),
            tx_offset: w(2),
            tx_size: w(3),
        };
    }
    if let Some((_, out)) = device.sync_manager(&SmKind::MBoxOut) {
        h.standard_mailbox.rx_offset = out.start_address;
        h.standard_mailbox.rx_size = out.default_size.unwrap_or(0);
    }
    if let Some((_, inp)) = device.sync_manager(&SmKind::MBoxIn) {
        h.standard_mailbox.tx_offset = inp.start_address;
        h.standard_mailbox.tx_size = inp.default_size.unwrap_or(0);
    }
    if let Some(mb) = &device.mailbox {
        use sii::mailbox_protocols as p;
        for (on, bit) in [
            (mb.aoe, p::AOE),
            (mb.eoe, p::EOE),
            (mb.coe.is_some(), p::COE),
            (mb.foe, p::FOE),
            (mb.soe, p::SOE),
            (mb.voe, p::VOE),
        ] {
            if on {
                h.mailbox_protocols |= bit;
            }
        }
    }
    let bytes = eeprom
        .and_then(|e| e.byte_size)
        .unwrap_or(DEFAULT_EEPROM_BYTES);
    // stored as KiBit - 1 = bytes / 128 - 1
    h.eeprom_size = u16::try_from((bytes / 128).max(1) - 1).map_err(|_| {
        SiiError::Encode(format!(
            "EEPROM ByteSize {bytes} does not fit the SII header"
        ))
    })?;
    Ok(h)
}

/// SII TxPDO / RxPDO records of the ESI PDOs (names added to the strings).
fn pdos(c: &mut SiiContent, esi: &[super::Pdo]) -> Result<Vec<sii::Pdo>, SiiError> {
    let mut out = Vec::with_capacity(esi.len());
    for p in esi {
        let name_idx = add(c, &p.name);
        let mut entries = Vec::with_capacity(p.entries.len());
        for e in &p.entries {
            let bit_len = u8::try_from(e.bit_len).map_err(|_| {
                SiiError::Encode(format!(
                    "PDO 0x{:04X} entry 0x{:04X}:{:02X}: BitLen {} does not fit 8 bits",
                    p.index, e.index, e.subindex, e.bit_len
                ))
            })?;
            entries.push(sii::PdoEntry {
                index: e.index,
                sub_index: e.subindex,
                name_idx: add(c, e.name.as_deref().unwrap_or("")),
                data_type: data_type_code(e.data_type.as_deref().unwrap_or("")),
                bit_len,
                flags: 0,
            });
        }
        let mut flags = 0u16;
        if p.mandatory {
            flags |= 0x0001;
        }
        if p.sm.is_some() {
            flags |= 0x0002;
        }
        if p.fixed {
            flags |= 0x0010;
        }
        out.push(sii::Pdo {
            index: p.index,
            sync_manager: p.sm.unwrap_or(0xFF),
            dc_sync: 0,
            name_idx,
            flags,
            entries,
        });
    }
    Ok(out)
}

/// Add a string (Latin-1, at most 255 bytes); 0 for an empty text or a full table.
fn add(c: &mut SiiContent, s: &str) -> u8 {
    let latin1: String = s
        .chars()
        .map(|ch| if u32::from(ch) <= 0xFF { ch } else { '?' })
        .take(255)
        .collect();
    c.add_string(&latin1).unwrap_or(0)
}

/// SII SyncManager type of an `Sm` kind.
fn sm_type(kind: &SmKind) -> u8 {
    match kind {
        SmKind::MBoxOut => sii::sm_type::MAILBOX_OUT,
        SmKind::MBoxIn => sii::sm_type::MAILBOX_IN,
        SmKind::Outputs => sii::sm_type::OUTPUTS,
        SmKind::Inputs => sii::sm_type::INPUTS,
        SmKind::Other(_) => sii::sm_type::UNUSED,
    }
}

/// Physical port nibbles of a `Physics` attribute (`Y` MII = 1, `E` EBUS = 3, others unused).
fn physical_ports(physics: &str) -> u16 {
    if physics == "EBUS" {
        return 0x0033;
    }
    physics
        .chars()
        .take(4)
        .enumerate()
        .fold(0u16, |acc, (i, ch)| {
            let code = match ch {
                'Y' => 1,
                'E' => 3,
                _ => 0,
            };
            acc | code << (4 * i)
        })
}

/// CiA 301 data type code of an ESI base type name (0 when unknown, e.g. a `BITn` or a
/// structure).
pub fn data_type_code(name: &str) -> u8 {
    match name {
        "BOOL" | "BIT" => 0x01,
        "SINT" => 0x02,
        "INT" => 0x03,
        "DINT" => 0x04,
        "USINT" | "BYTE" => 0x05,
        "UINT" | "WORD" => 0x06,
        "UDINT" | "DWORD" => 0x07,
        "REAL" => 0x08,
        "LREAL" => 0x11,
        "LINT" => 0x15,
        "ULINT" => 0x1B,
        _ => 0,
    }
}

/// A DC time in ns as the 32-bit SII value (negative shifts two's complement).
fn time(v: Option<i64>, what: &str) -> Result<u32, SiiError> {
    let v = v.unwrap_or(0);
    if let Ok(u) = u32::try_from(v) {
        Ok(u)
    } else if let Ok(i) = i32::try_from(v) {
        Ok(u32::from_le_bytes(i.to_le_bytes()))
    } else {
        Err(SiiError::Encode(format!("{what} {v} does not fit 32 bits")))
    }
}

/// A DC factor as the 16-bit SII value.
fn factor(v: Option<i64>, what: &str) -> Result<i16, SiiError> {
    let v = v.unwrap_or(0);
    i16::try_from(v).map_err(|_| SiiError::Encode(format!("{what} {v} does not fit 16 bits")))
}
