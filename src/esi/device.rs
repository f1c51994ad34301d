//! The device description read from an ESI file (ETG.2000 element names in the doc comments).
//! The dictionary types are in [`dictionary`](super::Dictionary), profiles in
//! [`Profile`](super::Profile), modules and slots in [`Module`](super::Module).
//!
//! Numbers are kept as the ESI writes them (`#x1A00` hex or decimal), already converted; names
//! of data types are kept as text (`UINT`, `DT1018`) and resolved through
//! [`Dictionary::data_type`]. Codes the parser does not know (an `Sm` text such as `MBoxState`,
//! an unknown `Fmmu` text) are kept as [`SmKind::Other`] / [`FmmuKind::Other`] instead of
//! failing, like the wire codecs of this crate keep unknown codes.

use super::{Dictionary, EsiWarning, Module, Object, PluggedModule, Profile, Slots};
use std::sync::Arc;

/// One ESI file: `EtherCATInfo` (ETG.2000 §4).
#[derive(Debug, Clone, PartialEq)]
pub struct EsiFile {
    /// The file name the description was read from (as given to [`super::parse`]).
    pub file: String,
    /// `EtherCATInfo/Vendor`.
    pub vendor: Vendor,
    /// `Descriptions/Groups/Group`.
    pub groups: Vec<Group>,
    /// `Descriptions/Devices/Device`.
    pub devices: Vec<Device>,
    /// `Descriptions/Modules/Module` (ETG.2000 modular devices; shared with the devices whose
    /// slots take them, [`Device::modules`]).
    pub modules: Vec<Arc<Module>>,
    /// Values read another way than written, or left out (see [`EsiWarning`]); empty for a
    /// file that follows ETG.2000.
    pub warnings: Vec<EsiWarning>,
}

impl EsiFile {
    /// The device with this product code and revision (`Type ProductCode`, `RevisionNo`).
    pub fn device(&self, product_code: u32, revision_no: u32) -> Option<&Device> {
        self.devices
            .iter()
            .find(|d| d.product_code == product_code && d.revision_no == revision_no)
    }

    /// The first device with this product code (any revision).
    pub fn device_by_product(&self, product_code: u32) -> Option<&Device> {
        self.devices.iter().find(|d| d.product_code == product_code)
    }
}

/// `Vendor`: the EtherCAT vendor ID (ETG.1000.6 SII word 0x0008, CoE 0x1018:01) and name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Vendor {
    /// `Vendor/Id`.
    pub id: u32,
    /// `Vendor/Name` (first one), empty if absent.
    pub name: String,
}

/// A localised name: `Name LcId="1033"` (LcId is a Windows locale ID, 1033 = en-US).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LocalName {
    /// `LcId` attribute, if given.
    pub lcid: Option<u32>,
    /// The text.
    pub text: String,
}

/// Pick the English (1033) name, else the first one.
fn pick_name(names: &[LocalName]) -> Option<&str> {
    names
        .iter()
        .find(|n| n.lcid == Some(1033))
        .or_else(|| names.first())
        .map(|n| n.text.as_str())
}

/// `Descriptions/Groups/Group`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Group {
    /// `Group/Type`: the key devices refer to with `GroupType`.
    pub group_type: String,
    /// `Group/Name`.
    pub names: Vec<LocalName>,
}

/// `Descriptions/Devices/Device`.
#[derive(Debug, Clone, PartialEq)]
pub struct Device {
    /// `Device Physics` attribute (port physics, e.g. `YY`), if given.
    pub physics: Option<String>,
    /// `Type` text (order number, e.g. `EL5101`).
    pub type_name: String,
    /// `Type ProductCode` (SII word 0x000A, CoE 0x1018:02).
    pub product_code: u32,
    /// `Type RevisionNo` (SII word 0x000C, CoE 0x1018:03); 0 when the attribute is absent.
    pub revision_no: u32,
    /// `Name` elements.
    pub names: Vec<LocalName>,
    /// `GroupType`.
    pub group: Option<String>,
    /// `Fmmu` elements, in order (FMMU 0, 1, …).
    pub fmmus: Vec<FmmuKind>,
    /// `Sm` elements, in order (SM 0, 1, …).
    pub sync_managers: Vec<SyncManager>,
    /// `RxPdo` elements (master → device).
    pub rx_pdos: Vec<Pdo>,
    /// `TxPdo` elements (device → master).
    pub tx_pdos: Vec<Pdo>,
    /// `Mailbox`; `None` for a device without mailbox (e.g. a coupler).
    pub mailbox: Option<Mailbox>,
    /// `Dc/OpMode` elements.
    pub dc_op_modes: Vec<DcOpMode>,
    /// `Profile`, if given.
    pub profile: Option<Profile>,
    /// `Eeprom`, if given.
    pub eeprom: Option<Eeprom>,
    /// `Slots`: the device is modular (ETG.2000 §4 "Modules and slots"); `None` for a device
    /// without slots.
    pub slots: Option<Slots>,
    /// The modules of the file (`Descriptions/Modules/Module`) that [`Device::slots`] name, in
    /// file order.
    pub modules: Vec<Arc<Module>>,
    /// `None`: the device as the file describes it. `Some`: a device resolved with a module
    /// per slot ([`Device::resolve`]); its PDOs and dictionary then include the modules'.
    pub plugged: Option<Vec<PluggedModule>>,
}

impl Device {
    /// The English (LcId 1033) name, else the first `Name`, else the `Type` text.
    pub fn name(&self) -> &str {
        pick_name(&self.names).unwrap_or(&self.type_name)
    }

    /// The RxPDO with this index (e.g. 0x1600).
    pub fn rx_pdo(&self, index: u16) -> Option<&Pdo> {
        self.rx_pdos.iter().find(|p| p.index == index)
    }

    /// The TxPDO with this index (e.g. 0x1A00).
    pub fn tx_pdo(&self, index: u16) -> Option<&Pdo> {
        self.tx_pdos.iter().find(|p| p.index == index)
    }

    /// The CoE object dictionary (`Profile/Dictionary`), if the file has one.
    pub fn dictionary(&self) -> Option<&Dictionary> {
        self.profile.as_ref().and_then(|p| p.dictionary.as_ref())
    }

    /// The dictionary object with this index.
    pub fn object(&self, index: u16) -> Option<&Object> {
        self.dictionary().and_then(|d| d.object(index))
    }

    /// The DC operation mode with this `Name`.
    pub fn dc_op_mode(&self, name: &str) -> Option<&DcOpMode> {
        self.dc_op_modes.iter().find(|m| m.name == name)
    }

    /// The sync manager of this kind (the first one, by SM number).
    pub fn sync_manager(&self, kind: &SmKind) -> Option<(usize, &SyncManager)> {
        self.sync_managers
            .iter()
            .enumerate()
            .find(|(_, sm)| &sm.kind == kind)
    }
}

/// What an `Fmmu` element is used for (its text).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FmmuKind {
    /// `Outputs`.
    Outputs,
    /// `Inputs`.
    Inputs,
    /// `MBoxState` (mailbox status bit, ETG.1000.4).
    MBoxState,
    /// Any other text, kept.
    Other(String),
}

/// What a sync manager is used for (the `Sm` text).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SmKind {
    /// `MBoxOut`: mailbox master → device.
    MBoxOut,
    /// `MBoxIn`: mailbox device → master.
    MBoxIn,
    /// `Outputs`: process data master → device.
    Outputs,
    /// `Inputs`: process data device → master.
    Inputs,
    /// Any other text (including empty), kept.
    Other(String),
}

/// `Sm`: one sync manager (ETG.1000.4 §6.7, registers 0x0800 + 8·n).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SyncManager {
    /// The `Sm` text.
    pub kind: SmKind,
    /// `StartAddress` (physical address in the ESC memory).
    pub start_address: u16,
    /// `DefaultSize` in bytes, if given.
    pub default_size: Option<u16>,
    /// `MinSize` in bytes, if given.
    pub min_size: Option<u16>,
    /// `MaxSize` in bytes, if given.
    pub max_size: Option<u16>,
    /// `ControlByte` (register 0x0804 + 8·n: mode, direction, interrupts, watchdog).
    pub control_byte: u8,
    /// `Enable` (register 0x0806 + 8·n bit 0); false when absent.
    pub enable: bool,
}

/// `RxPdo` / `TxPdo`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pdo {
    /// `Index` (0x1600.. for RxPDOs, 0x1A00.. for TxPDOs).
    pub index: u16,
    /// `Name` (first one), empty if absent.
    pub name: String,
    /// `Sm` attribute: the sync manager this PDO is assigned to by default; `None` = not
    /// assigned by default.
    pub sm: Option<u8>,
    /// `Fixed` attribute: the mapping cannot be changed.
    pub fixed: bool,
    /// `Mandatory` attribute: the PDO must be assigned.
    pub mandatory: bool,
    /// `Exclude` elements: PDOs that cannot be assigned together with this one.
    pub excludes: Vec<u16>,
    /// `Entry` elements, in mapping order.
    pub entries: Vec<PdoEntry>,
    /// `Index DependOnSlot`: in a module, the index moves by the slot number ×
    /// `SlotPdoIncrement` ([`Device::resolve`]).
    pub depend_on_slot: bool,
}

impl Pdo {
    /// Sum of the entries' bit lengths.
    pub fn bit_len(&self) -> u32 {
        self.entries.iter().map(|e| u32::from(e.bit_len)).sum()
    }
}

/// `Entry` of a PDO: one mapped object (or a gap with index 0).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PdoEntry {
    /// `Index`; 0 for a padding gap.
    pub index: u16,
    /// `SubIndex`; 0 when absent (allowed for gaps).
    pub subindex: u8,
    /// `BitLen`.
    pub bit_len: u16,
    /// `Name` (first one), if given.
    pub name: Option<String>,
    /// `DataType` text (e.g. `UINT`), if given.
    pub data_type: Option<String>,
    /// `Index DependOnSlot`: in a module, the index moves by the slot number ×
    /// `SlotIndexIncrement` ([`Device::resolve`]).
    pub depend_on_slot: bool,
}

impl PdoEntry {
    /// The CiA 301 mapping value `index << 16 | subindex << 8 | bit length` (as written to
    /// 0x1600:n / 0x1A00:n).
    pub fn mapping_value(&self) -> u32 {
        u32::from(self.index) << 16 | u32::from(self.subindex) << 8 | u32::from(self.bit_len & 0xFF)
    }
}

/// `Mailbox`: supported mailbox protocols.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Mailbox {
    /// `DataLinkLayer` attribute (mailbox data link layer, repeat support).
    pub data_link_layer: bool,
    /// `CoE`, if supported.
    pub coe: Option<Coe>,
    /// `SoE` present.
    pub soe: bool,
    /// `EoE` present.
    pub eoe: bool,
    /// `FoE` present.
    pub foe: bool,
    /// `AoE` present.
    pub aoe: bool,
    /// `VoE` present.
    pub voe: bool,
}

/// `Mailbox/CoE` attributes (all false when absent; other attributes and `InitCmd` elements
/// are not kept).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Coe {
    /// `SdoInfo`: SDO information service (object dictionary upload).
    pub sdo_info: bool,
    /// `PdoAssign`: PDO assignment (0x1C12/0x1C13) is writable.
    pub pdo_assign: bool,
    /// `PdoConfig`: PDO mapping (0x16xx/0x1Axx) is writable.
    pub pdo_config: bool,
    /// `PdoUpload`: the device reports its PDO configuration.
    pub pdo_upload: bool,
    /// `CompleteAccess`: SDO complete access.
    pub complete_access: bool,
    /// `SegmentedSdo`: segmented SDO transfer.
    pub segmented_sdo: bool,
}

/// A DC time value with its optional `Factor` attribute (`CycleTimeSync0 Factor="1"`).
///
/// ETG.2000: with a factor, the time is `factor × cycle time + value` (ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DcTime {
    /// The element text, ns.
    pub value: i64,
    /// `Factor` attribute, if given.
    pub factor: Option<i64>,
}

/// `Dc/OpMode`: one distributed-clock operation mode.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DcOpMode {
    /// `Name` (e.g. `DCSync`).
    pub name: String,
    /// `Desc`, if given.
    pub desc: Option<String>,
    /// `AssignActivate`: value for ESC register 0x0980 (0x0300 = SYNC0 on, cyclic unit on).
    pub assign_activate: u16,
    /// `CycleTimeSync0`.
    pub cycle_time_sync0: Option<DcTime>,
    /// `ShiftTimeSync0`.
    pub shift_time_sync0: Option<DcTime>,
    /// `CycleTimeSync1`.
    pub cycle_time_sync1: Option<DcTime>,
    /// `ShiftTimeSync1`.
    pub shift_time_sync1: Option<DcTime>,
}

/// `Eeprom`: SII size and configuration area.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Eeprom {
    /// `ByteSize`, if given.
    pub byte_size: Option<u32>,
    /// `ConfigData` bytes (SII words 0x0000..), if given.
    pub config_data: Option<Vec<u8>>,
    /// `BootStrap` bytes (bootstrap mailbox offsets/sizes), if given.
    pub boot_strap: Option<Vec<u8>>,
}
