//! EtherCAT Slave Information (ETG.2000 XML) → device description, and the SII EEPROM image
//! ([`sii`]).
//!
//! [`parse`] reads one `EtherCATInfo` document into an [`EsiFile`]: the vendor, and per device
//! its identity, names, group, sync managers, FMMUs, RxPDOs / TxPDOs with their entries,
//! mailbox protocols, DC operation modes, EEPROM configuration data, its profiles
//! ([`Profile`] with `ChannelInfo`), the CoE object dictionary (`Profile/Dictionary`), and for
//! a modular device its `Slots` and the file's `Modules`. [`load`] reads a file from disk first.
//!
//! Files are read the way their makers' tools (TwinCAT, the ETG conformance tool) read them:
//! a value in a form ETG.2000 does not define but with one reading (odd-length hexBinary
//! `<DefaultData>0</DefaultData>` = `00`, `0x1A00`, `TRUE`) is read that way, an optional
//! value without a reading (an `Access` of `rx`) is left out; each is an [`EsiWarning`] in
//! [`EsiFile::warnings`] (`file:line:col: path: subject: what was read`), many alike in one
//! warning. The readings are listed in `docs/interpretations.md` (section ESI files).
//!
//! Numbers follow ETG.2000: `#x1A00` is hexadecimal, anything else decimal. `DefaultData` and
//! EEPROM data are hexBinary byte strings (little-endian values, as on the wire);
//! `DefaultValue` / `MinValue` / `MaxValue` are numbers ([`InfoValues`]).
//!
//! Errors — for what cannot be read: not well-formed XML, a missing `Vendor/Id` or
//! `Type ProductCode`, a PDO entry without `Index` — never panic and name the file, the line
//! and column, and the element path
//! (`EtherCATInfo/Descriptions/Devices/Device/RxPdo[2]/Entry[3]`), e.g.
//!
//! ```text
//! drive.xml:12218:13: EtherCATInfo/Descriptions/Devices/Device/RxPdo[1]/Entry[1]: missing element <Index>
//! ```
//!
//! Choosing a device of a file (type name, product code and revision, position) and plugging
//! modules into its slots is [`select`]: [`resolve`] gives the [`Resolved`] device every
//! consumer (emulator, SII builder, drive definitions) uses. The profile questions
//! ([`Device::is_cia402`], [`Device::is_mdp_servo`], [`Device::profile_numbers`],
//! [`Device::device_type`]) are methods of [`Device`].
//!
//! The files the emulator plays live in the repository folder `esi/`.

mod device;
mod dictionary;
mod modules;
mod parse;
mod profile;
mod scan;
pub mod select;
pub mod sii;
pub mod to_sii;
mod values;
mod warn;

pub use device::*;
pub use dictionary::*;
pub use modules::*;
pub use profile::*;
pub use select::{resolve, split_spec, DeviceSelector, Resolved, SelectError, Selector};
pub use warn::{EsiWarning, Oddity, Place};

use std::path::Path;

/// What is wrong with an element (the `problem` of [`EsiError::Invalid`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Problem {
    /// A required child element is absent.
    #[error("missing element <{0}>")]
    MissingElement(String),
    /// A required attribute is absent.
    #[error("missing attribute {0}")]
    MissingAttribute(String),
    /// Element text is not a number (`#x` hex or decimal).
    #[error("not a number: {0:?} (expected #x hex or decimal)")]
    BadNumber(String),
    /// Element text is a number outside the range of its field.
    #[error("number out of range: {0:?}")]
    OutOfRange(String),
    /// An attribute value is not valid (not a number, out of range, not a boolean).
    #[error("bad value of attribute {0}: {1:?}")]
    BadAttribute(String, String),
    /// Element text is not an allowed value (e.g. `Access` other than ro / rw / wo).
    #[error("unexpected value {0:?}")]
    BadValue(String),
    /// Element text is not hexBinary (pairs of hex digits).
    #[error("not hex bytes: {0:?}")]
    BadHexBinary(String),
    /// Sync managers whose memory areas overlap or extend beyond the 64 KiB ESC address space
    /// (ETG.1000.4: each sync manager owns its own area of ESC memory); such a device never
    /// answers on the emulated bus. The text names both sync managers or the end address.
    #[error("{0}")]
    SyncManagerLayout(String),
    /// The document is well-formed XML but not something this parser supports.
    #[error("unsupported: {0}")]
    Unsupported(String),
}

/// Errors of [`parse`] and [`load`].
#[derive(Debug, thiserror::Error)]
pub enum EsiError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Io {
        /// File name.
        file: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The bytes are neither UTF-8 nor declared ISO-8859-1.
    #[error("{file}: not UTF-8 text (and not declared ISO-8859-1) at byte {offset}")]
    Encoding {
        /// File name.
        file: String,
        /// Byte offset of the first invalid sequence.
        offset: usize,
    },
    /// The text is not well-formed XML.
    #[error("{file}:{line}:{column}: not well-formed XML: {message}")]
    Xml {
        /// File name.
        file: String,
        /// 1-based line.
        line: u32,
        /// 1-based column.
        column: u32,
        /// The XML parser's message.
        message: String,
    },
    /// The file is above one of the limits of [`crate::limits`] (checked before the XML
    /// parser runs).
    #[error("{file}:{line}:{column}: {message}")]
    Limit {
        /// File name.
        file: String,
        /// 1-based line.
        line: u32,
        /// 1-based column.
        column: u32,
        /// Which limit, and its value.
        message: String,
    },
    /// Well-formed XML that is not a valid / supported ESI description.
    #[error("{file}:{line}:{column}: {path}: {problem}")]
    Invalid {
        /// File name.
        file: String,
        /// 1-based line of the element (or attribute) at fault.
        line: u32,
        /// 1-based column.
        column: u32,
        /// Element path from the root, e.g. `EtherCATInfo/Descriptions/Devices/Device/RxPdo[2]`.
        path: String,
        /// What is wrong.
        problem: Problem,
    },
}

impl EsiError {
    /// The 1-based line the error points at, if it has one.
    pub fn line(&self) -> Option<u32> {
        match self {
            EsiError::Xml { line, .. }
            | EsiError::Limit { line, .. }
            | EsiError::Invalid { line, .. } => Some(*line),
            _ => None,
        }
    }

    /// The element path the error points at, if it has one.
    pub fn path(&self) -> Option<&str> {
        match self {
            EsiError::Invalid { path, .. } => Some(path),
            _ => None,
        }
    }
}

/// Parse the text of an ESI file. `file` is used in error messages and kept in
/// [`EsiFile::file`].
pub fn parse(text: &str, file: &str) -> Result<EsiFile, EsiError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let opts = roxmltree::ParsingOptions {
        allow_dtd: false,
        ..Default::default()
    };
    let max = crate::limits::MAX_ESI_ATTRIBUTES_PER_ELEMENT;
    if let Some((offset, name)) = scan::too_many_attributes(text, max) {
        let (line, column) = end_position(&text[..offset]);
        return Err(EsiError::Limit {
            file: file.to_string(),
            line,
            column,
            message: format!(
                "element <{name}> has more than {max} attributes, the limit of an ESI element \
                 (docs/limits.md)"
            ),
        });
    }
    let doc = roxmltree::Document::parse_with_options(text, opts).map_err(|e| {
        let (line, column, message) = match e {
            // roxmltree reports these at 1:1; a truncated file is better named by its end and
            // the elements still open there
            roxmltree::Error::UnclosedRootNode | roxmltree::Error::UnexpectedEndOfStream => {
                let (line, column) = end_position(text);
                let open = scan::open_elements(text);
                let message = if open.is_empty() {
                    format!("{e} (file truncated?)")
                } else {
                    format!("{e}: file ends inside {open} (truncated?)")
                };
                (line, column, message)
            }
            _ => (e.pos().row, e.pos().col, e.to_string()),
        };
        EsiError::Xml {
            file: file.to_string(),
            line,
            column,
            message,
        }
    })?;
    parse::parse_document(&doc, file)
}

/// 1-based line and column just after the last character of `text`.
fn end_position(text: &str) -> (u32, u32) {
    let line = text.matches('\n').count() + 1;
    let last = text.rsplit('\n').next().unwrap_or("");
    let column = last.chars().count() + 1;
    (
        u32::try_from(line).unwrap_or(u32::MAX),
        u32::try_from(column).unwrap_or(u32::MAX),
    )
}

/// Parse the bytes of an ESI file: UTF-8 (with or without BOM), or ISO-8859-1 when the XML
/// declaration says so (some vendor tools write Latin-1).
pub fn parse_bytes(bytes: &[u8], file: &str) -> Result<EsiFile, EsiError> {
    match std::str::from_utf8(bytes) {
        Ok(text) => parse(text, file),
        Err(e) => {
            let head = &bytes[..bytes.len().min(200)];
            let head = String::from_utf8_lossy(head).to_ascii_lowercase();
            if head.contains("iso-8859-1") || head.contains("latin1") {
                let text: String = bytes.iter().map(|&b| char::from(b)).collect();
                parse(&text, file)
            } else {
                Err(EsiError::Encoding {
                    file: file.to_string(),
                    offset: e.valid_up_to(),
                })
            }
        }
    }
}

/// Read and parse an ESI file.
pub fn load(path: impl AsRef<Path>) -> Result<EsiFile, EsiError> {
    let path = path.as_ref();
    let file = path.display().to_string();
    let bytes = crate::limits::read_file(path, "ESI file", crate::limits::MAX_ESI_FILE_BYTES)
        .map_err(|source| EsiError::Io {
            file: file.clone(),
            source,
        })?;
    parse_bytes(&bytes, &file)
}
