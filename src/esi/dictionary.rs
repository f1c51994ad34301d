//! The CoE object dictionary of an ESI device (`Profile/Dictionary`, ETG.2000 element names in
//! the doc comments).

/// `Profile/Dictionary`: the CoE object dictionary.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Dictionary {
    /// `DataTypes/DataType`.
    pub data_types: Vec<DataType>,
    /// `Objects/Object`.
    pub objects: Vec<Object>,
}

impl Dictionary {
    /// The object with this index.
    pub fn object(&self, index: u16) -> Option<&Object> {
        self.objects.iter().find(|o| o.index == index)
    }

    /// The data type with this name (`UINT`, `DT1018`).
    pub fn data_type(&self, name: &str) -> Option<&DataType> {
        self.data_types.iter().find(|t| t.name == name)
    }
}

/// `DataType`: a base type, a record (with `SubItem`s) or an array (`BaseType` + `ArrayInfo`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DataType {
    /// `Name`.
    pub name: String,
    /// `BaseType` (array element type), if given.
    pub base_type: Option<String>,
    /// `BitSize`.
    pub bit_size: u32,
    /// `ArrayInfo`, if given.
    pub array: Option<ArrayInfo>,
    /// `SubItem` elements (records, and arrays written out with sub-index 0).
    pub subitems: Vec<DataTypeSubItem>,
}

/// `DataType/ArrayInfo`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ArrayInfo {
    /// `LBound`: first sub-index of the elements.
    pub lbound: u32,
    /// `Elements`: number of elements.
    pub elements: u32,
}

/// `DataType/SubItem`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DataTypeSubItem {
    /// `SubIdx`, if given (absent for the element of an array).
    pub subindex: Option<u8>,
    /// `Name`.
    pub name: String,
    /// `Type`.
    pub type_name: String,
    /// `BitSize`.
    pub bit_size: u32,
    /// `BitOffs`.
    pub bit_offs: u32,
    /// `Flags`.
    pub flags: Flags,
}

/// `Flags` of an object or sub-item.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Flags {
    /// `Access`, if given.
    pub access: Option<Access>,
    /// `Access WriteRestrictions` attribute (e.g. `PreOP`), if given.
    pub write_restrictions: Option<String>,
    /// `PdoMapping`, if given.
    pub pdo_mapping: Option<PdoMapping>,
    /// `Category` (`m` mandatory, `o` optional, `c` conditional), if given.
    pub category: Option<String>,
}

/// `Flags/Access`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// `ro`.
    ReadOnly,
    /// `rw`.
    ReadWrite,
    /// `wo`.
    WriteOnly,
}

/// `Flags/PdoMapping`: in which PDO direction the object may be mapped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PdoMapping {
    /// `R`: RxPDO (master → device).
    Rx,
    /// `T`: TxPDO (device → master).
    Tx,
    /// `RT` / `TR`: both.
    RxTx,
}

impl PdoMapping {
    /// Mappable into an RxPDO.
    pub fn rx(self) -> bool {
        matches!(self, PdoMapping::Rx | PdoMapping::RxTx)
    }

    /// Mappable into a TxPDO.
    pub fn tx(self) -> bool {
        matches!(self, PdoMapping::Tx | PdoMapping::RxTx)
    }
}

/// `Objects/Object`: one dictionary entry.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Object {
    /// `Index`.
    pub index: u16,
    /// `Index DependOnSlot`: in a module's dictionary, the index moves by the slot number ×
    /// `SlotIndexIncrement`.
    pub depend_on_slot: bool,
    /// `Name` (first one).
    pub name: String,
    /// `Type`: a data type name of the dictionary.
    pub type_name: String,
    /// `BitSize`.
    pub bit_size: u32,
    /// `Info/DefaultData`: the default value's bytes (ETG.2000 hexBinary, little-endian, as on
    /// the wire), if given; else the UTF-8 bytes of `Info/DefaultString` (a STRING default).
    pub default_data: Option<Vec<u8>>,
    /// `Info/DefaultValue`, `MinValue`, `MaxValue`: numbers (`#x` hex or decimal, not
    /// hexBinary), if given.
    pub values: InfoValues,
    /// `Flags` (empty when absent: records carry flags per sub-item in the data type).
    pub flags: Flags,
    /// `Info/SubItem` elements (per-sub-index defaults of a record or array).
    pub subitems: Vec<ObjectSubItem>,
}

impl Object {
    /// The default value as an unsigned little-endian number (up to 8 bytes) from
    /// `DefaultData`.
    pub fn default_u64(&self) -> Option<u64> {
        self.default_data.as_deref().and_then(le_u64)
    }

    /// The default value as the file gives it: `DefaultData` zero-extended (up to 8 bytes,
    /// little-endian; shorter data than the type is zero-extended), else `DefaultValue`
    /// (a negative value as its 64-bit two's complement). `None` when the file gives neither.
    pub fn default_number(&self) -> Option<u64> {
        default_number(self.default_data.as_deref(), self.values.default)
    }
}

fn default_number(data: Option<&[u8]>, value: Option<i128>) -> Option<u64> {
    match data {
        Some(d) => le_u64(d),
        None => value.and_then(|v| {
            u64::try_from(v)
                .ok()
                .or_else(|| i64::try_from(v).ok().map(|v| v as u64))
        }),
    }
}

/// `Object/Info/SubItem`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectSubItem {
    /// `Name`.
    pub name: String,
    /// `Info/DefaultData` bytes (else `Info/DefaultString`'s UTF-8 bytes), if given.
    pub default_data: Option<Vec<u8>>,
    /// `Info/DefaultValue`, `MinValue`, `MaxValue`, if given.
    pub values: InfoValues,
}

/// The numeric values of an `Info` element (ETG.2000 `DefaultValue`, `MinValue`, `MaxValue`):
/// numbers as written (`#x00020192` or decimal, possibly negative), unlike the hexBinary
/// `DefaultData`. A file gives either form, or none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InfoValues {
    /// `DefaultValue`.
    pub default: Option<i128>,
    /// `MinValue`.
    pub min: Option<i128>,
    /// `MaxValue`.
    pub max: Option<i128>,
}

impl ObjectSubItem {
    /// The default value as an unsigned little-endian number (up to 8 bytes) from
    /// `DefaultData`.
    pub fn default_u64(&self) -> Option<u64> {
        self.default_data.as_deref().and_then(le_u64)
    }

    /// As [`Object::default_number`].
    pub fn default_number(&self) -> Option<u64> {
        default_number(self.default_data.as_deref(), self.values.default)
    }
}

fn le_u64(b: &[u8]) -> Option<u64> {
    if b.is_empty() || b.len() > 8 {
        return None;
    }
    Some(
        b.iter()
            .rev()
            .fold(0u64, |acc, &byte| acc << 8 | u64::from(byte)),
    )
}
