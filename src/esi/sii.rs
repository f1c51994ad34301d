//! SII EEPROM images (ETG.1000.6 §5.4, ETG.2010): build from a device description, decode real
//! images.
//!
//! The SII (Slave Information Interface) EEPROM of an EtherCAT SubDevice holds a fixed header of
//! 64 little-endian words (bytes `0x00..0x80`: PDI configuration, configured station alias, a
//! CRC-8 over words 0–6, identity, mailbox layout, EEPROM size) followed by a chain of
//! categories, each `type: u16, length_in_words: u16, data`, terminated by type `0xFFFF`.
//!
//! * [`encode`] builds the minimal image (header, categories, End marker); [`encode_padded`]
//!   additionally fills up to the EEPROM size declared in the header with `0xFF`.
//! * [`decode`] parses an image. Unknown categories (vendor specific `0x0800..`, SyncUnit,
//!   DataTypes, …) are kept raw in [`Category::Unknown`] in their original order, so re-encoding a
//!   decoded image reproduces the bytes up to and including the End marker. Malformed lengths and
//!   truncation give an [`SiiError`] naming the byte offset and category; decoding never panics.
//! * **Header checksum policy:** [`decode`] verifies the CRC-8 (poly 0x07, init 0xFF, over bytes
//!   `0..14`, stored in the low byte of word 7) and returns [`SiiError::HeaderChecksum`] on a
//!   mismatch. [`decode_ignoring_checksum`] parses such images anyway. The checksum is not part
//!   of [`SiiHeader`]: [`encode`] always computes it.
//! * [`encode`] refuses flag bytes with bits that ETG.2010 leaves undefined (ethercrab's
//!   `bitflags::from_bits` rejects those and aborts the SubDevice init); see
//!   [`SiiContent::check_defined_bits`]. [`decode`] accepts them.
//! * [`load_image`] reads a file's bytes in any of the formats found in the wild: raw binary
//!   (ethercrab's `dumps/eeprom/*.hex` are in fact raw binary), Intel HEX ([`parse_intel_hex`])
//!   or a plain whitespace-separated hex dump ([`parse_hex_dump`]).

/// Size in bytes of the fixed header (words `0x00..0x40`).
pub const HEADER_LEN: usize = 0x80;

/// Category type codes (ETG.2010 Table 3).
pub mod category_type {
    /// Strings.
    pub const STRINGS: u16 = 10;
    /// Data types (not decoded, kept raw).
    pub const DATA_TYPES: u16 = 20;
    /// General.
    pub const GENERAL: u16 = 30;
    /// FMMU usage.
    pub const FMMU: u16 = 40;
    /// SyncManager.
    pub const SYNC_MANAGER: u16 = 41;
    /// FMMU extended (not decoded, kept raw).
    pub const FMMU_EX: u16 = 42;
    /// SyncUnit (not decoded, kept raw).
    pub const SYNC_UNIT: u16 = 43;
    /// TxPDO (inputs, SubDevice → MainDevice).
    pub const TX_PDO: u16 = 50;
    /// RxPDO (outputs, MainDevice → SubDevice).
    pub const RX_PDO: u16 = 51;
    /// Distributed clock op modes.
    pub const DC: u16 = 60;
    /// End of the category chain.
    pub const END: u16 = 0xFFFF;
}

/// Mailbox protocol bits (header word 0x1C).
pub mod mailbox_protocols {
    /// ADS over EtherCAT.
    pub const AOE: u16 = 0x0001;
    /// Ethernet over EtherCAT.
    pub const EOE: u16 = 0x0002;
    /// CANopen over EtherCAT.
    pub const COE: u16 = 0x0004;
    /// File access over EtherCAT.
    pub const FOE: u16 = 0x0008;
    /// Servo drive profile over EtherCAT.
    pub const SOE: u16 = 0x0010;
    /// Vendor specific over EtherCAT.
    pub const VOE: u16 = 0x0020;
    /// All defined bits.
    pub const DEFINED: u16 = 0x003F;
}

/// CoE details bits (General category byte 5).
pub mod coe_details {
    /// SDO supported.
    pub const SDO: u8 = 0x01;
    /// SDO information supported.
    pub const SDO_INFO: u8 = 0x02;
    /// PDO assignment writable.
    pub const PDO_ASSIGN: u8 = 0x04;
    /// PDO configuration writable.
    pub const PDO_CONFIG: u8 = 0x08;
    /// PDO configuration uploaded at startup.
    pub const UPLOAD_AT_STARTUP: u8 = 0x10;
    /// SDO complete access supported.
    pub const COMPLETE_ACCESS: u8 = 0x20;
    /// All defined bits.
    pub const DEFINED: u8 = 0x3F;
}

/// General category flag bits (General category byte 11).
pub mod general_flags {
    /// SAFE-OP may be entered without process data outputs ("enable SafeOp").
    pub const ENABLE_SAFEOP: u8 = 0x01;
    /// LRW must not be used ("enable notLRW").
    pub const ENABLE_NOT_LRW: u8 = 0x02;
    /// Mailbox data link layer supported.
    pub const MBOX_DLL: u8 = 0x04;
    /// Identification via AL status code.
    pub const IDENT_AL_STATUS: u8 = 0x08;
    /// Identification via physical memory.
    pub const IDENT_PHYS_MEM: u8 = 0x10;
    /// All defined bits.
    pub const DEFINED: u8 = 0x1F;
}

/// SyncManager enable bits (SyncManager entry byte 6).
pub mod sm_enable {
    /// SyncManager enabled.
    pub const ENABLE: u8 = 0x01;
    /// Fixed content (not configurable).
    pub const FIXED: u8 = 0x02;
    /// Virtual SyncManager.
    pub const VIRTUAL: u8 = 0x04;
    /// Used in OP only.
    pub const OP_ONLY: u8 = 0x08;
    /// All defined bits.
    pub const DEFINED: u8 = 0x0F;
}

/// SyncManager type codes (SyncManager entry byte 7).
pub mod sm_type {
    /// Unused / unknown (derive from the control byte).
    pub const UNUSED: u8 = 0;
    /// Mailbox out (MainDevice → SubDevice).
    pub const MAILBOX_OUT: u8 = 1;
    /// Mailbox in (SubDevice → MainDevice).
    pub const MAILBOX_IN: u8 = 2;
    /// Process data outputs.
    pub const OUTPUTS: u8 = 3;
    /// Process data inputs.
    pub const INPUTS: u8 = 4;
}

/// FMMU usage codes (one byte per FMMU).
pub mod fmmu_usage {
    /// Not used.
    pub const UNUSED: u8 = 0x00;
    /// Process data outputs.
    pub const OUTPUTS: u8 = 0x01;
    /// Process data inputs.
    pub const INPUTS: u8 = 0x02;
    /// SyncManager status (mailbox state).
    pub const SM_STATUS: u8 = 0x03;
    /// Not used (alternative encoding).
    pub const UNUSED_FF: u8 = 0xFF;
}

/// Errors from decoding, encoding or loading SII images.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SiiError {
    /// The image is shorter than the 128-byte fixed header.
    #[error("SII image too short: {len} bytes, the fixed header needs 128")]
    TooShort {
        /// Image length in bytes.
        len: usize,
    },
    /// The CRC-8 over bytes 0..14 does not match the low byte of word 7.
    #[error(
        "SII header checksum mismatch at byte offset 0x000E: stored 0x{stored:02X}, computed \
         0x{computed:02X} (CRC-8 poly 0x07 init 0xFF over bytes 0..14)"
    )]
    HeaderChecksum {
        /// Checksum byte found in the image.
        stored: u8,
        /// Checksum computed over bytes 0..14.
        computed: u8,
    },
    /// The image ends inside a 4-byte category header.
    #[error(
        "category header at byte offset 0x{offset:04X} truncated: the image ends at 0x{len:04X} \
         (no End category 0xFFFF)"
    )]
    TruncatedCategoryHeader {
        /// Byte offset of the category header.
        offset: usize,
        /// Image length in bytes.
        len: usize,
    },
    /// A category's declared length runs past the end of the image.
    #[error(
        "{name} category (type 0x{category_type:04X}) at byte offset 0x{offset:04X} declares \
         {words} words, but the image ends at 0x{len:04X}"
    )]
    CategoryOverrun {
        /// Category name.
        name: &'static str,
        /// Category type code.
        category_type: u16,
        /// Byte offset of the category header.
        offset: usize,
        /// Declared length in words.
        words: u16,
        /// Image length in bytes.
        len: usize,
    },
    /// A known category's content is malformed.
    #[error(
        "{name} category (type 0x{category_type:04X}) at byte offset 0x{offset:04X}: {reason}"
    )]
    BadCategory {
        /// Category name.
        name: &'static str,
        /// Category type code.
        category_type: u16,
        /// Byte offset of the problem.
        offset: usize,
        /// What is wrong.
        reason: String,
    },
    /// The content cannot be encoded (value out of range, undefined flag bits, …).
    #[error("cannot encode SII image: {0}")]
    Encode(String),
    /// A malformed line in an Intel HEX file or hex dump.
    #[error("hex line {line}: {reason}")]
    Hex {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

/// The fixed header, words `0x00..0x40` (ETG.1000.6 Table 16), without the checksum (word 7),
/// which [`encode`] computes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SiiHeader {
    /// Word 0x00: PDI control (initial value of ESC register 0x0140).
    pub pdi_control: u16,
    /// Word 0x01: PDI configuration (register 0x0150).
    pub pdi_config: u16,
    /// Word 0x02: sync impulse length in 10 ns units (register 0x0982).
    pub sync_impulse_len: u16,
    /// Word 0x03: extended PDI configuration (register 0x0152).
    pub pdi_config2: u16,
    /// Word 0x04: configured station alias (register 0x0012).
    pub station_alias: u16,
    /// Words 0x05..0x07: reserved, kept as read.
    pub reserved_05: [u8; 4],
    /// Word 0x08: vendor id.
    pub vendor_id: u32,
    /// Word 0x0A: product code.
    pub product_code: u32,
    /// Word 0x0C: revision number.
    pub revision: u32,
    /// Word 0x0E: serial number.
    pub serial: u32,
    /// Word 0x10: execution delay (ns).
    pub execution_delay: u16,
    /// Word 0x11: port 0 delay (ns).
    pub port0_delay: u16,
    /// Word 0x12: port 1 delay (ns).
    pub port1_delay: u16,
    /// Word 0x13: reserved, kept as read.
    pub reserved_13: u16,
    /// Words 0x14..0x18: bootstrap mailbox.
    pub bootstrap_mailbox: MailboxLayout,
    /// Words 0x18..0x1C: standard mailbox.
    pub standard_mailbox: MailboxLayout,
    /// Word 0x1C: supported mailbox protocols ([`mailbox_protocols`]).
    pub mailbox_protocols: u16,
    /// Words 0x1D..0x3E: reserved (66 bytes), kept as read; all zero in a fresh image.
    pub reserved_1d: Vec<u8>,
    /// Word 0x3E: EEPROM size as stored: size in KiBit minus one, i.e. `(v + 1) * 128` bytes.
    pub eeprom_size: u16,
    /// Word 0x3F: version (1 for ETG.2010 images).
    pub version: u16,
}

impl Default for SiiHeader {
    fn default() -> Self {
        Self {
            pdi_control: 0,
            pdi_config: 0,
            sync_impulse_len: 0,
            pdi_config2: 0,
            station_alias: 0,
            reserved_05: [0; 4],
            vendor_id: 0,
            product_code: 0,
            revision: 0,
            serial: 0,
            execution_delay: 0,
            port0_delay: 0,
            port1_delay: 0,
            reserved_13: 0,
            bootstrap_mailbox: MailboxLayout::default(),
            standard_mailbox: MailboxLayout::default(),
            mailbox_protocols: 0,
            reserved_1d: vec![0; RESERVED_1D_LEN],
            eeprom_size: 0,
            version: 1,
        }
    }
}

const RESERVED_1D_LEN: usize = (0x3E - 0x1D) * 2;

impl SiiHeader {
    /// EEPROM size in bytes, `(eeprom_size + 1) * 128`.
    pub fn eeprom_size_bytes(&self) -> usize {
        (usize::from(self.eeprom_size) + 1) * 128
    }
}

/// Receive/send mailbox offsets and sizes (bytes, ESC memory addresses).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MailboxLayout {
    /// Receive (MainDevice → SubDevice) mailbox start address.
    pub rx_offset: u16,
    /// Receive mailbox size.
    pub rx_size: u16,
    /// Send (SubDevice → MainDevice) mailbox start address.
    pub tx_offset: u16,
    /// Send mailbox size.
    pub tx_size: u16,
}

/// The General category (type 30, 32 bytes; ETG.2010 Table 5). A shorter category in an image
/// decodes with the missing bytes as zero (and re-encodes as 32 bytes).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct General {
    /// Byte 0: string index of the group type.
    pub group_idx: u8,
    /// Byte 1: string index of the image name.
    pub image_idx: u8,
    /// Byte 2: string index of the order number (ethercrab `name()`).
    pub order_idx: u8,
    /// Byte 3: string index of the device name (ethercrab `description()`).
    pub name_idx: u8,
    /// Byte 4: reserved (older images: physical layer), kept as read.
    pub reserved_4: u8,
    /// Byte 5: CoE details ([`coe_details`]).
    pub coe_details: u8,
    /// Byte 6: FoE details (bit 0: FoE supported).
    pub foe_details: u8,
    /// Byte 7: EoE details (bit 0: EoE supported).
    pub eoe_details: u8,
    /// Byte 8: number of SoE channels.
    pub soe_channels: u8,
    /// Byte 9: number of DS402 channels.
    pub ds402_channels: u8,
    /// Byte 10: SysmanClass (reserved).
    pub sysman_class: u8,
    /// Byte 11: flags ([`general_flags`]).
    pub flags: u8,
    /// Bytes 12..14: current consumption on E-bus in mA (negative: feeds the E-bus).
    pub current_on_ebus: i16,
    /// Byte 14: group string index, duplicate kept for compatibility.
    pub group_idx2: u8,
    /// Byte 15: reserved, kept as read.
    pub reserved_15: u8,
    /// Bytes 16..18: physical ports, 4 bits per port (0 unused, 1 MII, 2 reserved, 3 EBUS, …).
    pub physical_ports: u16,
    /// Bytes 18..20: physical memory address (identification).
    pub physical_memory_address: u16,
    /// Bytes 20..32: reserved, kept as read.
    pub reserved_20: [u8; 12],
    /// Bytes beyond 32 (non-standard longer category), kept as read.
    pub extra: Vec<u8>,
}

/// One SyncManager (SyncManager category, 8 bytes each).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SyncManager {
    /// Physical start address.
    pub start: u16,
    /// Length in bytes (0 for process data SMs sized by the MainDevice).
    pub length: u16,
    /// Control register value (register 0x0804 + 8n).
    pub control: u8,
    /// Status register value (byte 5; "reserved" in ETG.2010, normally 0).
    pub status: u8,
    /// Enable bits ([`sm_enable`]).
    pub enable: u8,
    /// SyncManager type ([`sm_type`]).
    pub sm_type: u8,
}

/// One PDO entry (8 bytes).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PdoEntry {
    /// Object index (0 for a gap).
    pub index: u16,
    /// Object sub-index.
    pub sub_index: u8,
    /// String index of the entry name.
    pub name_idx: u8,
    /// Data type code (ETG.1000.6 / CiA 301: 1 BOOL, 2 INT8, 3 INT16, 4 INT32, 5 UINT8,
    /// 6 UINT16, 7 UINT32, …).
    pub data_type: u8,
    /// Bit length.
    pub bit_len: u8,
    /// Flags (reserved, normally 0).
    pub flags: u16,
}

/// One PDO (8-byte header + entries).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Pdo {
    /// PDO index (0x1600.. for RxPDOs, 0x1A00.. for TxPDOs).
    pub index: u16,
    /// SyncManager the PDO is assigned to by default (0xFF: not assigned).
    pub sync_manager: u8,
    /// DC sync unit.
    pub dc_sync: u8,
    /// String index of the PDO name.
    pub name_idx: u8,
    /// PDO flags (bit 0 mandatory, bit 1 default, bit 4 fixed content, …).
    pub flags: u16,
    /// The mapped entries.
    pub entries: Vec<PdoEntry>,
}

/// Data type codes used in PDO entries (CiA 301 / ETG.1000.6 basic types).
pub mod data_type {
    /// BOOLEAN.
    pub const BOOL: u8 = 0x01;
    /// INTEGER8.
    pub const INT8: u8 = 0x02;
    /// INTEGER16.
    pub const INT16: u8 = 0x03;
    /// INTEGER32.
    pub const INT32: u8 = 0x04;
    /// UNSIGNED8.
    pub const UINT8: u8 = 0x05;
    /// UNSIGNED16.
    pub const UINT16: u8 = 0x06;
    /// UNSIGNED32.
    pub const UINT32: u8 = 0x07;
}

/// One distributed-clock op mode (DC category, 24 bytes each).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DcOpMode {
    /// SYNC0 cycle time (ns, 0 = from the MainDevice's cycle).
    pub cycle_time_0: u32,
    /// SYNC0 shift time (ns).
    pub shift_time_0: u32,
    /// SYNC1 shift time (ns).
    pub shift_time_1: u32,
    /// SYNC1 cycle time as a factor of SYNC0.
    pub sync1_cycle_factor: i16,
    /// Value for ESC register 0x0980 (AssignActivate, e.g. 0x0300 for SYNC0).
    pub assign_activate: u16,
    /// SYNC0 cycle time as a factor of the bus cycle.
    pub sync0_cycle_factor: i16,
    /// String index of the op-mode name.
    pub name_idx: u8,
    /// String index of the op-mode description.
    pub desc_idx: u8,
    /// Reserved bytes, kept as read.
    pub reserved: [u8; 4],
}

/// One category of the chain after the fixed header.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Category {
    /// Strings (type 10). Index 1 is the first string; 0 means "no string". Bytes are mapped
    /// 1:1 to chars (Latin-1), so any byte string survives a round trip. Bytes after the last
    /// string (beyond the one pad byte to a whole word) are not kept.
    Strings(Vec<String>),
    /// General (type 30).
    General(General),
    /// FMMU usage bytes (type 40), one per FMMU ([`fmmu_usage`]). A pad byte of an odd count is
    /// kept as read (it decodes as one more FMMU).
    Fmmu(Vec<u8>),
    /// SyncManagers (type 41).
    SyncManagers(Vec<SyncManager>),
    /// TxPDOs (type 50).
    TxPdos(Vec<Pdo>),
    /// RxPDOs (type 51).
    RxPdos(Vec<Pdo>),
    /// DC op modes (type 60).
    Dc(Vec<DcOpMode>),
    /// Any other category, kept raw (data is a whole number of words).
    Unknown {
        /// Category type code.
        category_type: u16,
        /// Raw data.
        data: Vec<u8>,
    },
}

impl Category {
    /// Category type code.
    pub fn type_code(&self) -> u16 {
        match self {
            Category::Strings(_) => category_type::STRINGS,
            Category::General(_) => category_type::GENERAL,
            Category::Fmmu(_) => category_type::FMMU,
            Category::SyncManagers(_) => category_type::SYNC_MANAGER,
            Category::TxPdos(_) => category_type::TX_PDO,
            Category::RxPdos(_) => category_type::RX_PDO,
            Category::Dc(_) => category_type::DC,
            Category::Unknown { category_type, .. } => *category_type,
        }
    }
}

/// Human-readable name of a category type code.
pub fn category_name(code: u16) -> &'static str {
    match code {
        category_type::STRINGS => "Strings",
        category_type::DATA_TYPES => "DataTypes",
        category_type::GENERAL => "General",
        category_type::FMMU => "FMMU",
        category_type::SYNC_MANAGER => "SyncManager",
        category_type::FMMU_EX => "FMMU_EX",
        category_type::SYNC_UNIT => "SyncUnit",
        category_type::TX_PDO => "TxPDO",
        category_type::RX_PDO => "RxPDO",
        category_type::DC => "DC",
        category_type::END => "End",
        0x0800..=0x0FFF => "vendor specific",
        _ => "unknown",
    }
}

/// A whole SII image: fixed header plus categories in EEPROM order.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SiiContent {
    /// Fixed header (words 0x00..0x40).
    pub header: SiiHeader,
    /// Categories in the order they appear (the End marker is implicit).
    pub categories: Vec<Category>,
}

impl SiiContent {
    /// The first Strings category's strings (empty if none).
    pub fn strings(&self) -> &[String] {
        self.categories
            .iter()
            .find_map(|c| match c {
                Category::Strings(s) => Some(s.as_slice()),
                _ => None,
            })
            .unwrap_or(&[])
    }

    /// String by SII index (1-based; 0 or out of range → `None`).
    pub fn string(&self, idx: u8) -> Option<&str> {
        let i = usize::from(idx).checked_sub(1)?;
        self.strings().get(i).map(String::as_str)
    }

    /// Index of `s` in the Strings category, adding it if it is not there yet (a Strings
    /// category is inserted first if the content has none). Empty `s` gives 0 ("no string").
    /// Fails when 255 strings are already present.
    pub fn add_string(&mut self, s: &str) -> Result<u8, SiiError> {
        if s.is_empty() {
            return Ok(0);
        }
        let pos = match self
            .categories
            .iter()
            .position(|c| matches!(c, Category::Strings(_)))
        {
            Some(p) => p,
            None => {
                self.categories.insert(0, Category::Strings(Vec::new()));
                0
            }
        };
        let Category::Strings(strings) = &mut self.categories[pos] else {
            unreachable!("position() found a Strings category");
        };
        if let Some(i) = strings.iter().position(|x| x == s) {
            // A hand-built table may hold more than 255 strings; beyond that no index fits.
            return u8::try_from(i + 1).map_err(|_| {
                SiiError::Encode(format!(
                    "string {s:?} is number {} of the table; at most 255",
                    i + 1
                ))
            });
        }
        if strings.len() >= 255 {
            return Err(SiiError::Encode(format!(
                "cannot add string {s:?}: 255 strings already"
            )));
        }
        strings.push(s.to_string());
        Ok(u8::try_from(strings.len()).expect("checked above"))
    }

    /// The General category, if present.
    pub fn general(&self) -> Option<&General> {
        self.categories.iter().find_map(|c| match c {
            Category::General(g) => Some(g),
            _ => None,
        })
    }

    /// FMMU usage bytes (empty if no FMMU category).
    pub fn fmmus(&self) -> &[u8] {
        self.categories
            .iter()
            .find_map(|c| match c {
                Category::Fmmu(f) => Some(f.as_slice()),
                _ => None,
            })
            .unwrap_or(&[])
    }

    /// SyncManagers (empty if no SyncManager category).
    pub fn sync_managers(&self) -> &[SyncManager] {
        self.categories
            .iter()
            .find_map(|c| match c {
                Category::SyncManagers(s) => Some(s.as_slice()),
                _ => None,
            })
            .unwrap_or(&[])
    }

    /// All TxPDOs (of all TxPDO categories, in order).
    pub fn tx_pdos(&self) -> impl Iterator<Item = &Pdo> {
        self.categories
            .iter()
            .filter_map(|c| match c {
                Category::TxPdos(p) => Some(p.iter()),
                _ => None,
            })
            .flatten()
    }

    /// All RxPDOs (of all RxPDO categories, in order).
    pub fn rx_pdos(&self) -> impl Iterator<Item = &Pdo> {
        self.categories
            .iter()
            .filter_map(|c| match c {
                Category::RxPdos(p) => Some(p.iter()),
                _ => None,
            })
            .flatten()
    }

    /// DC op modes (empty if no DC category).
    pub fn dc_op_modes(&self) -> &[DcOpMode] {
        self.categories
            .iter()
            .find_map(|c| match c {
                Category::Dc(d) => Some(d.as_slice()),
                _ => None,
            })
            .unwrap_or(&[])
    }

    /// Check that the flag bytes only use bits ETG.2010 defines (ethercrab rejects others):
    /// mailbox protocols, General flags and CoE details, SyncManager enable and type, FMMU usage.
    pub fn check_defined_bits(&self) -> Result<(), SiiError> {
        let e = |m: String| Err(SiiError::Encode(m));
        let p = self.header.mailbox_protocols;
        if p & !mailbox_protocols::DEFINED != 0 {
            return e(format!("mailbox protocols 0x{p:04X} has undefined bits"));
        }
        for c in &self.categories {
            match c {
                Category::General(g) => {
                    if g.flags & !general_flags::DEFINED != 0 {
                        return e(format!(
                            "General flags 0x{:02X} has undefined bits",
                            g.flags
                        ));
                    }
                    if g.coe_details & !coe_details::DEFINED != 0 {
                        return e(format!(
                            "General CoE details 0x{:02X} has undefined bits",
                            g.coe_details
                        ));
                    }
                }
                Category::SyncManagers(sms) => {
                    for (i, sm) in sms.iter().enumerate() {
                        if sm.enable & !sm_enable::DEFINED != 0 {
                            return e(format!(
                                "SM{i} enable 0x{:02X} has undefined bits",
                                sm.enable
                            ));
                        }
                        if sm.sm_type > sm_type::INPUTS {
                            return e(format!("SM{i} type {} is undefined", sm.sm_type));
                        }
                    }
                }
                Category::Fmmu(f) => {
                    for (i, &u) in f.iter().enumerate() {
                        if !matches!(u, 0..=3 | 0xFF) {
                            return e(format!("FMMU{i} usage 0x{u:02X} is undefined"));
                        }
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }
}

/// CRC-8 as used for the SII header checksum: polynomial 0x07, initial value 0xFF, no
/// reflection, no final XOR.
pub fn crc8(data: &[u8]) -> u8 {
    let mut crc: u8 = 0xFF;
    for &b in data {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x07
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// Header checksum of an image: [`crc8`] over bytes `0..14` (`None` if the image is shorter).
pub fn header_checksum(image: &[u8]) -> Option<u8> {
    image.get(..14).map(crc8)
}

// ---------------------------------------------------------------------------------------------
// encode

fn put16(out: &mut Vec<u8>, v: u16) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn encode_header(h: &SiiHeader) -> Result<Vec<u8>, SiiError> {
    if h.reserved_1d.len() != RESERVED_1D_LEN {
        return Err(SiiError::Encode(format!(
            "header reserved_1d must be {RESERVED_1D_LEN} bytes, is {}",
            h.reserved_1d.len()
        )));
    }
    let mut out = Vec::with_capacity(HEADER_LEN);
    put16(&mut out, h.pdi_control);
    put16(&mut out, h.pdi_config);
    put16(&mut out, h.sync_impulse_len);
    put16(&mut out, h.pdi_config2);
    put16(&mut out, h.station_alias);
    out.extend_from_slice(&h.reserved_05);
    let crc = crc8(&out);
    put16(&mut out, u16::from(crc));
    put32(&mut out, h.vendor_id);
    put32(&mut out, h.product_code);
    put32(&mut out, h.revision);
    put32(&mut out, h.serial);
    put16(&mut out, h.execution_delay);
    put16(&mut out, h.port0_delay);
    put16(&mut out, h.port1_delay);
    put16(&mut out, h.reserved_13);
    for m in [h.bootstrap_mailbox, h.standard_mailbox] {
        put16(&mut out, m.rx_offset);
        put16(&mut out, m.rx_size);
        put16(&mut out, m.tx_offset);
        put16(&mut out, m.tx_size);
    }
    put16(&mut out, h.mailbox_protocols);
    out.extend_from_slice(&h.reserved_1d);
    put16(&mut out, h.eeprom_size);
    put16(&mut out, h.version);
    debug_assert_eq!(out.len(), HEADER_LEN);
    Ok(out)
}

fn encode_pdos(pdos: &[Pdo], out: &mut Vec<u8>) -> Result<(), SiiError> {
    for p in pdos {
        let n = u8::try_from(p.entries.len()).map_err(|_| {
            SiiError::Encode(format!("PDO 0x{:04X} has more than 255 entries", p.index))
        })?;
        put16(out, p.index);
        out.push(n);
        out.push(p.sync_manager);
        out.push(p.dc_sync);
        out.push(p.name_idx);
        put16(out, p.flags);
        for e in &p.entries {
            put16(out, e.index);
            out.push(e.sub_index);
            out.push(e.name_idx);
            out.push(e.data_type);
            out.push(e.bit_len);
            put16(out, e.flags);
        }
    }
    Ok(())
}

fn encode_category(c: &Category) -> Result<Vec<u8>, SiiError> {
    let mut d = Vec::new();
    match c {
        Category::Strings(strings) => {
            let n = u8::try_from(strings.len())
                .map_err(|_| SiiError::Encode("more than 255 strings".into()))?;
            d.push(n);
            for s in strings {
                let bytes: Vec<u8> = s
                    .chars()
                    .map(|ch| {
                        u8::try_from(u32::from(ch)).map_err(|_| {
                            SiiError::Encode(format!("string {s:?} has a non-Latin-1 char {ch:?}"))
                        })
                    })
                    .collect::<Result<_, _>>()?;
                let len = u8::try_from(bytes.len()).map_err(|_| {
                    SiiError::Encode(format!("string {s:?} is longer than 255 bytes"))
                })?;
                d.push(len);
                d.extend_from_slice(&bytes);
            }
        }
        Category::General(g) => {
            d.extend_from_slice(&[
                g.group_idx,
                g.image_idx,
                g.order_idx,
                g.name_idx,
                g.reserved_4,
                g.coe_details,
                g.foe_details,
                g.eoe_details,
                g.soe_channels,
                g.ds402_channels,
                g.sysman_class,
                g.flags,
            ]);
            d.extend_from_slice(&g.current_on_ebus.to_le_bytes());
            d.push(g.group_idx2);
            d.push(g.reserved_15);
            put16(&mut d, g.physical_ports);
            put16(&mut d, g.physical_memory_address);
            d.extend_from_slice(&g.reserved_20);
            d.extend_from_slice(&g.extra);
        }
        Category::Fmmu(f) => d.extend_from_slice(f),
        Category::SyncManagers(sms) => {
            for sm in sms {
                put16(&mut d, sm.start);
                put16(&mut d, sm.length);
                d.extend_from_slice(&[sm.control, sm.status, sm.enable, sm.sm_type]);
            }
        }
        Category::TxPdos(p) | Category::RxPdos(p) => encode_pdos(p, &mut d)?,
        Category::Dc(modes) => {
            for m in modes {
                put32(&mut d, m.cycle_time_0);
                put32(&mut d, m.shift_time_0);
                put32(&mut d, m.shift_time_1);
                d.extend_from_slice(&m.sync1_cycle_factor.to_le_bytes());
                put16(&mut d, m.assign_activate);
                d.extend_from_slice(&m.sync0_cycle_factor.to_le_bytes());
                d.push(m.name_idx);
                d.push(m.desc_idx);
                d.extend_from_slice(&m.reserved);
            }
        }
        Category::Unknown {
            category_type,
            data,
        } => {
            if *category_type == category_type::END {
                return Err(SiiError::Encode(
                    "an Unknown category cannot use type 0xFFFF (End)".into(),
                ));
            }
            d.extend_from_slice(data);
        }
    }
    if d.len() % 2 == 1 {
        d.push(0);
    }
    let words = u16::try_from(d.len() / 2).map_err(|_| {
        SiiError::Encode(format!(
            "{} category longer than 65535 words",
            category_name(c.type_code())
        ))
    })?;
    let mut out = Vec::with_capacity(d.len() + 4);
    put16(&mut out, c.type_code());
    put16(&mut out, words);
    out.extend_from_slice(&d);
    Ok(out)
}

/// Build the SII image: 128-byte header (checksum computed), the categories in order (each
/// padded to whole words), then the End marker `0xFFFF`. The image is not padded to the EEPROM
/// size (see [`encode_padded`]).
///
/// Fails on values that do not fit the format (more than 255 strings or PDO entries, strings
/// longer than 255 bytes or not Latin-1, oversized categories) and on flag bytes with undefined
/// bits ([`SiiContent::check_defined_bits`]).
pub fn encode(content: &SiiContent) -> Result<Vec<u8>, SiiError> {
    content.check_defined_bits()?;
    let mut out = encode_header(&content.header)?;
    for c in &content.categories {
        out.extend(encode_category(c)?);
    }
    put16(&mut out, category_type::END);
    Ok(out)
}

/// [`encode`], then fill with `0xFF` (erased EEPROM) up to the size declared in the header
/// (`(eeprom_size + 1) * 128` bytes); fails if the image does not fit.
pub fn encode_padded(content: &SiiContent) -> Result<Vec<u8>, SiiError> {
    let mut out = encode(content)?;
    let size = content.header.eeprom_size_bytes();
    if out.len() > size {
        return Err(SiiError::Encode(format!(
            "image needs {} bytes but the header declares an EEPROM of {size} bytes",
            out.len()
        )));
    }
    out.resize(size, 0xFF);
    Ok(out)
}

// ---------------------------------------------------------------------------------------------
// decode

fn le16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn le32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn decode_header(b: &[u8]) -> SiiHeader {
    let mb = |at: usize| MailboxLayout {
        rx_offset: le16(b, at),
        rx_size: le16(b, at + 2),
        tx_offset: le16(b, at + 4),
        tx_size: le16(b, at + 6),
    };
    SiiHeader {
        pdi_control: le16(b, 0x00),
        pdi_config: le16(b, 0x02),
        sync_impulse_len: le16(b, 0x04),
        pdi_config2: le16(b, 0x06),
        station_alias: le16(b, 0x08),
        reserved_05: [b[0x0A], b[0x0B], b[0x0C], b[0x0D]],
        vendor_id: le32(b, 0x10),
        product_code: le32(b, 0x14),
        revision: le32(b, 0x18),
        serial: le32(b, 0x1C),
        execution_delay: le16(b, 0x20),
        port0_delay: le16(b, 0x22),
        port1_delay: le16(b, 0x24),
        reserved_13: le16(b, 0x26),
        bootstrap_mailbox: mb(0x28),
        standard_mailbox: mb(0x30),
        mailbox_protocols: le16(b, 0x38),
        reserved_1d: b[0x3A..0x7C].to_vec(),
        eeprom_size: le16(b, 0x7C),
        version: le16(b, 0x7E),
    }
}

/// Decode an SII image, verifying the header checksum ([`SiiError::HeaderChecksum`] on a
/// mismatch). Bytes after the End marker are ignored.
pub fn decode(image: &[u8]) -> Result<SiiContent, SiiError> {
    decode_inner(image, true)
}

/// [`decode`] without the header checksum check (for images with a stale or unset checksum).
pub fn decode_ignoring_checksum(image: &[u8]) -> Result<SiiContent, SiiError> {
    decode_inner(image, false)
}

fn decode_inner(image: &[u8], check_crc: bool) -> Result<SiiContent, SiiError> {
    if image.len() < HEADER_LEN {
        return Err(SiiError::TooShort { len: image.len() });
    }
    if check_crc {
        let computed = crc8(&image[..14]);
        let stored = image[14];
        if computed != stored {
            return Err(SiiError::HeaderChecksum { stored, computed });
        }
    }
    let header = decode_header(image);
    let mut categories = Vec::new();
    let mut at = HEADER_LEN;
    loop {
        if at + 2 > image.len() {
            return Err(SiiError::TruncatedCategoryHeader {
                offset: at,
                len: image.len(),
            });
        }
        let ty = le16(image, at);
        if ty == category_type::END {
            break;
        }
        if at + 4 > image.len() {
            return Err(SiiError::TruncatedCategoryHeader {
                offset: at,
                len: image.len(),
            });
        }
        let words = le16(image, at + 2);
        let start = at + 4;
        let end = start + usize::from(words) * 2;
        if end > image.len() {
            return Err(SiiError::CategoryOverrun {
                name: category_name(ty),
                category_type: ty,
                offset: at,
                words,
                len: image.len(),
            });
        }
        categories.push(decode_category(ty, &image[start..end], start)?);
        at = end;
    }
    Ok(SiiContent { header, categories })
}

fn bad(ty: u16, offset: usize, reason: String) -> SiiError {
    SiiError::BadCategory {
        name: category_name(ty),
        category_type: ty,
        offset,
        reason,
    }
}

fn decode_category(ty: u16, d: &[u8], base: usize) -> Result<Category, SiiError> {
    Ok(match ty {
        category_type::STRINGS => {
            let Some((&n, mut rest)) = d.split_first() else {
                return Err(bad(ty, base, "empty, no string count".into()));
            };
            let mut strings = Vec::with_capacity(usize::from(n));
            let mut pos = base + 1;
            for i in 0..n {
                let Some((&len, tail)) = rest.split_first() else {
                    return Err(bad(
                        ty,
                        pos,
                        format!("string {} of {n}: length byte past the category end", i + 1),
                    ));
                };
                let len = usize::from(len);
                if tail.len() < len {
                    return Err(bad(
                        ty,
                        pos,
                        format!(
                            "string {} of {n}: {len} bytes declared, only {} left in the category",
                            i + 1,
                            tail.len()
                        ),
                    ));
                }
                strings.push(tail[..len].iter().map(|&b| char::from(b)).collect());
                rest = &tail[len..];
                pos += 1 + len;
            }
            Category::Strings(strings)
        }
        category_type::GENERAL => {
            let mut b = [0u8; 32];
            let n = d.len().min(32);
            b[..n].copy_from_slice(&d[..n]);
            Category::General(General {
                group_idx: b[0],
                image_idx: b[1],
                order_idx: b[2],
                name_idx: b[3],
                reserved_4: b[4],
                coe_details: b[5],
                foe_details: b[6],
                eoe_details: b[7],
                soe_channels: b[8],
                ds402_channels: b[9],
                sysman_class: b[10],
                flags: b[11],
                current_on_ebus: i16::from_le_bytes([b[12], b[13]]),
                group_idx2: b[14],
                reserved_15: b[15],
                physical_ports: le16(&b, 16),
                physical_memory_address: le16(&b, 18),
                reserved_20: b[20..32].try_into().expect("12 bytes"),
                extra: d.get(32..).unwrap_or(&[]).to_vec(),
            })
        }
        category_type::FMMU => Category::Fmmu(d.to_vec()),
        category_type::SYNC_MANAGER => {
            if !d.len().is_multiple_of(8) {
                return Err(bad(
                    ty,
                    base,
                    format!("length {} bytes is not a multiple of 8", d.len()),
                ));
            }
            Category::SyncManagers(
                d.chunks_exact(8)
                    .map(|c| SyncManager {
                        start: le16(c, 0),
                        length: le16(c, 2),
                        control: c[4],
                        status: c[5],
                        enable: c[6],
                        sm_type: c[7],
                    })
                    .collect(),
            )
        }
        category_type::TX_PDO | category_type::RX_PDO => {
            let pdos = decode_pdos(ty, d, base)?;
            if ty == category_type::TX_PDO {
                Category::TxPdos(pdos)
            } else {
                Category::RxPdos(pdos)
            }
        }
        category_type::DC => {
            if !d.len().is_multiple_of(24) {
                return Err(bad(
                    ty,
                    base,
                    format!("length {} bytes is not a multiple of 24", d.len()),
                ));
            }
            Category::Dc(
                d.chunks_exact(24)
                    .map(|c| DcOpMode {
                        cycle_time_0: le32(c, 0),
                        shift_time_0: le32(c, 4),
                        shift_time_1: le32(c, 8),
                        sync1_cycle_factor: i16::from_le_bytes([c[12], c[13]]),
                        assign_activate: le16(c, 14),
                        sync0_cycle_factor: i16::from_le_bytes([c[16], c[17]]),
                        name_idx: c[18],
                        desc_idx: c[19],
                        reserved: [c[20], c[21], c[22], c[23]],
                    })
                    .collect(),
            )
        }
        _ => Category::Unknown {
            category_type: ty,
            data: d.to_vec(),
        },
    })
}

fn decode_pdos(ty: u16, d: &[u8], base: usize) -> Result<Vec<Pdo>, SiiError> {
    let mut pdos = Vec::new();
    let mut at = 0;
    while at < d.len() {
        if d.len() - at < 8 {
            return Err(bad(
                ty,
                base + at,
                format!(
                    "{} trailing bytes, too short for a PDO header (8)",
                    d.len() - at
                ),
            ));
        }
        let h = &d[at..at + 8];
        let n = usize::from(h[2]);
        let need = 8 + n * 8;
        if d.len() - at < need {
            return Err(bad(
                ty,
                base + at,
                format!(
                    "PDO 0x{:04X} declares {n} entries ({need} bytes), only {} left in the category",
                    le16(h, 0),
                    d.len() - at
                ),
            ));
        }
        let entries = d[at + 8..at + need]
            .chunks_exact(8)
            .map(|c| PdoEntry {
                index: le16(c, 0),
                sub_index: c[2],
                name_idx: c[3],
                data_type: c[4],
                bit_len: c[5],
                flags: le16(c, 6),
            })
            .collect();
        pdos.push(Pdo {
            index: le16(h, 0),
            sync_manager: h[3],
            dc_sync: h[4],
            name_idx: h[5],
            flags: le16(h, 6),
            entries,
        });
        at += need;
    }
    Ok(pdos)
}

// ---------------------------------------------------------------------------------------------
// file formats

/// Turn a file's bytes into an SII image: Intel HEX if the first non-blank character is `:`
/// and the file is ASCII, a plain hex dump if it only holds hex digits and whitespace (and at
/// least one digit), raw binary otherwise.
pub fn load_image(file: &[u8]) -> Result<Vec<u8>, SiiError> {
    let is_text = file
        .iter()
        .all(|&b| b.is_ascii_graphic() || b.is_ascii_whitespace());
    if is_text && !file.is_empty() {
        let text = std::str::from_utf8(file).expect("ASCII is UTF-8");
        let trimmed = text.trim_start();
        if trimmed.starts_with(':') {
            return parse_intel_hex(text);
        }
        if trimmed
            .bytes()
            .all(|b| b.is_ascii_hexdigit() || b.is_ascii_whitespace())
            && !trimmed.is_empty()
        {
            return parse_hex_dump(text);
        }
    }
    Ok(file.to_vec())
}

/// Parse a plain hex dump: whitespace-separated tokens of an even number of hex digits
/// (`"09 00 00 08"` or `"09000008"`); `#` starts a comment to the end of the line.
pub fn parse_hex_dump(text: &str) -> Result<Vec<u8>, SiiError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        for tok in line.split_whitespace() {
            let bytes = hex_bytes(tok).map_err(|reason| SiiError::Hex {
                line: i + 1,
                reason: format!("token {tok:?}: {reason}"),
            })?;
            out.extend(bytes);
        }
    }
    Ok(out)
}

fn hex_bytes(s: &str) -> Result<Vec<u8>, String> {
    if !s.is_ascii() {
        return Err("not ASCII hex".into());
    }
    if !s.len().is_multiple_of(2) {
        return Err(format!("odd number of hex digits ({})", s.len()));
    }
    (0..s.len())
        .step_by(2)
        .map(|i| {
            u8::from_str_radix(&s[i..i + 2], 16)
                .map_err(|_| format!("bad hex digits {:?}", &s[i..i + 2]))
        })
        .collect()
}

/// Largest image [`parse_intel_hex`] accepts (an SII EEPROM is at most 64 KiB words = 128 KiB,
/// ETG allows addresses up to 0xFFFF words).
pub const MAX_HEX_IMAGE: usize = 0x2_0000;

/// Parse Intel HEX (record types 00 data, 01 EOF, 02 extended segment address, 04 extended
/// linear address; 03/05 start addresses are ignored). The image starts at address 0; gaps are
/// filled with `0xFF`. Blank lines are skipped; anything after the EOF record is ignored.
/// Errors name the 1-based line number.
pub fn parse_intel_hex(text: &str) -> Result<Vec<u8>, SiiError> {
    let mut out: Vec<u8> = Vec::new();
    let mut base: usize = 0;
    let mut saw_eof = false;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let err = |reason: String| SiiError::Hex {
            line: line_no,
            reason,
        };
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        let Some(body) = line.strip_prefix(':') else {
            return Err(err("record does not start with ':'".into()));
        };
        let rec = hex_bytes(body).map_err(&err)?;
        if rec.len() < 5 {
            return Err(err(format!("record too short ({} bytes)", rec.len())));
        }
        let count = usize::from(rec[0]);
        if rec.len() != count + 5 {
            return Err(err(format!(
                "byte count {count} but the record holds {} data bytes",
                rec.len() - 5
            )));
        }
        let sum = rec.iter().fold(0u8, |a, &b| a.wrapping_add(b));
        if sum != 0 {
            return Err(err(format!(
                "checksum mismatch (record checksum 0x{:02X}, byte sum 0x{sum:02X} instead of 0x00)",
                rec[rec.len() - 1]
            )));
        }
        let addr = usize::from(u16::from_be_bytes([rec[1], rec[2]]));
        let data = &rec[4..4 + count];
        match rec[3] {
            0x00 => {
                let start = base + addr;
                let end = start + count;
                if end > MAX_HEX_IMAGE {
                    return Err(err(format!(
                        "data at address 0x{start:X} beyond the {MAX_HEX_IMAGE}-byte limit"
                    )));
                }
                if out.len() < end {
                    out.resize(end, 0xFF);
                }
                out[start..end].copy_from_slice(data);
            }
            0x01 => {
                saw_eof = true;
                break;
            }
            0x02 => {
                if count != 2 {
                    return Err(err("extended segment address record needs 2 bytes".into()));
                }
                base = usize::from(u16::from_be_bytes([data[0], data[1]])) * 16;
            }
            0x04 => {
                if count != 2 {
                    return Err(err("extended linear address record needs 2 bytes".into()));
                }
                base = usize::from(u16::from_be_bytes([data[0], data[1]])) << 16;
            }
            0x03 | 0x05 => {}
            t => return Err(err(format!("unknown record type 0x{t:02X}"))),
        }
    }
    if !saw_eof {
        return Err(SiiError::Hex {
            line: text.lines().count(),
            reason: "no EOF record (type 01)".into(),
        });
    }
    Ok(out)
}
