//! **Internal** (used by fieldprobe's readers and binary; may change in any release).
//!
//! Limits as policy, in one place: every cap on what a user file or option may make fieldprobe
//! allocate or compute, and the one helper through which every user file is read.
//!
//! A limit exists so that no input — a careless `list = "/dev/zero"`, a generated NC program of
//! ten million blocks, `--device X.xml:1000000` — can make the tool run out of memory, block
//! forever or take minutes. Each cap is far above what a real machine, program or vendor file
//! needs (the reason is on each constant) and each refusal names the file or option, the limit
//! and what was found; the command-line tool then exits 2 (bad input). The table of all caps is
//! `docs/limits.md`.
//!
//! Files are read with [`read_file`] / [`read_text`]: the path must name a *regular* file (a
//! character device such as `/dev/zero` or `/dev/urandom`, a FIFO, a socket or a directory is
//! refused before anything is read, so nothing blocks), and at most `cap + 1` bytes are read, so
//! a file that grows while it is read cannot exceed the cap either.

use std::io::Read;
use std::path::Path;

/// One mebibyte.
const MIB: u64 = 1024 * 1024;

/// Largest NC program file: 32 MiB. A generated program of 500,000 blocks of ~40 characters is
/// 20 MB; hand-written programs are kilobytes.
pub const MAX_NC_PROGRAM_BYTES: u64 = 32 * MIB;

/// Most NC blocks in one program: 500,000. A parsed program held ~0.8 KB per block (measured
/// by `benches/nc_parse.rs`: 788 bytes resident per block of ~31 source characters) before the
/// items were made smaller and the program shared by its clones (issue 28 item 9: a run of
/// 500,000 moves peaks at 152 MB), so this is a few hundred MB at most.
pub const MAX_NC_BLOCKS: usize = 500_000;

/// Longest NC line, and longest block joined from continued lines (`\` at the end, an open
/// `[`): 65,536 characters. Hand-written and CAM-generated blocks are well below 1,000
/// characters (a `#MSG SYN` with a long text a few hundred); the lexer holds a line as 12-byte
/// characters, so without the cap one 32 MiB line (inside [`MAX_NC_PROGRAM_BYTES`]) made the
/// parser peak near 1 GB. A block that reaches the cap by continuation is most often a `[`
/// that never closes.
pub const MAX_NC_LINE_CHARS: usize = 65_536;

/// Largest machine file (TOML): 4 MiB. A 32-axis machine with every parameter set explicitly is
/// below 1 MB.
pub const MAX_MACHINE_FILE_BYTES: u64 = 4 * MIB;

/// Largest ISG parameter list (`.lis`, `list = "…"` in a machine file): 4 MiB. A full axis list
/// of every seed parameter is a few hundred kilobytes.
pub const MAX_LIST_FILE_BYTES: u64 = 4 * MIB;

/// Largest drive definition file (`drives/*.toml` format): 1 MiB. The built-in ones are < 10 KB.
pub const MAX_DRIVE_FILE_BYTES: u64 = MIB;

/// Largest ESI file (ETG.2000 XML): 64 MiB. Vendor files describing a whole terminal family with
/// every revision reach ~30 MB.
pub const MAX_ESI_FILE_BYTES: u64 = 64 * MIB;

/// Most attributes on one ESI XML element: 256. ETG.2000 elements carry at most a dozen; the cap
/// keeps the XML reader's per-element duplicate-attribute check (quadratic in the attributes of
/// one element) linear in the file size.
pub const MAX_ESI_ATTRIBUTES_PER_ELEMENT: usize = 256;

/// Most slot instances of one modular ESI device resolved with its modules (ETG.2000 `Slots`):
/// 256. Modular EtherCAT devices have a few slots to a few dozen (a coupler with its terminals
/// up to 255); each instance copies its module's PDOs into the resolved device.
pub const MAX_ESI_SLOT_INSTANCES: usize = 256;

/// Most PDO entries and dictionary objects the modules of one resolved ESI device add: 262,144
/// (a few tens of MB). A module with hundreds of entries in 256 slots stays below it.
pub const MAX_ESI_RESOLVED_ITEMS: usize = 1 << 18;

/// Warnings one ESI file may give: 64, one per kind of odd value and element (the places of
/// each are counted, not kept). Further kinds are counted in one last warning.
pub const MAX_ESI_WARNINGS: usize = 64;

/// Places listed in one ESI warning besides the first: 8 (the rest are counted).
pub const MAX_ESI_WARNING_PLACES: usize = 8;

/// Largest EDS / DCF file (CiA 306): 16 MiB. Big multi-axis drives have EDS files of ~1 MB.
pub const MAX_EDS_FILE_BYTES: u64 = 16 * MIB;

/// Largest capture file read back whole (pcap / pcapng): 256 MiB.
pub const MAX_CAPTURE_FILE_BYTES: u64 = 256 * MIB;

/// Largest object the EtherCAT mailbox clients accept from a device: a CoE SDO upload (its
/// announced size, and the data of its segments) or an SoE element read joined from fragments:
/// 1 MiB, the same as the CANopen SDO client's default (`bus::canopen::sdo::DEFAULT_MAX_SIZE`).
/// A larger CoE upload is aborted with 0x0504_0005 "out of memory"; both end with
/// `bus::ethercat::mailbox::MailboxError::ObjectTooLarge`.
pub const MAX_MAILBOX_OBJECT_BYTES: usize = MIB as usize;

/// Most devices in one emulated EtherCAT segment (`sim ethercat --device FILE.xml:COUNT`):
/// 1024. The protocol allows 65,535 (16-bit auto-increment address), but every emulated
/// device holds its own 64 KiB ESC memory; 1024 devices are 64 MiB, and far more than any real
/// segment (a few hundred at most).
pub const MAX_SEGMENT_DEVICES: usize = 1024;

/// Read a whole user file that must be a regular file of at most `cap` bytes. `what` names the
/// kind of file in errors ("NC program", "ESI file"). The error never names the path (callers
/// wrap it with the file name, as they do for any I/O error); it names what is wrong and the
/// limit.
pub fn read_file(path: &Path, what: &str, cap: u64) -> std::io::Result<Vec<u8>> {
    // Metadata of what the path leads to: a symbolic link to a regular file is fine, one to a
    // device is a device.
    let meta = std::fs::metadata(path)?;
    check_regular(&meta, what)?;
    let file = open_nonblocking(path)?;
    // The path may have been replaced between the two calls: check what was opened.
    let meta = file.metadata()?;
    check_regular(&meta, what)?;
    if meta.len() > cap {
        return Err(too_large(what, cap, Some(meta.len())));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    file.take(cap.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(too_large(what, cap, None));
    }
    Ok(bytes)
}

/// [`read_file`] for a file that must be UTF-8 text.
pub fn read_text(path: &Path, what: &str, cap: u64) -> std::io::Result<String> {
    let bytes = read_file(path, what, cap)?;
    String::from_utf8(bytes).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "the {what} is not UTF-8 text (invalid byte at offset {})",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

fn check_regular(meta: &std::fs::Metadata, what: &str) -> std::io::Result<()> {
    if meta.is_file() {
        return Ok(());
    }
    let ft = meta.file_type();
    let kind = if ft.is_dir() {
        "a directory"
    } else {
        special_kind(&ft)
    };
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("{kind}, not a regular file; the {what} must be a regular file"),
    ))
}

#[cfg(unix)]
fn special_kind(ft: &std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if ft.is_char_device() {
        "a character device"
    } else if ft.is_block_device() {
        "a block device"
    } else if ft.is_fifo() {
        "a FIFO"
    } else if ft.is_socket() {
        "a socket"
    } else {
        "a special file"
    }
}

#[cfg(not(unix))]
fn special_kind(_: &std::fs::FileType) -> &'static str {
    "a special file"
}

/// Open for reading without blocking on a FIFO that was swapped in after the metadata check
/// (`O_NONBLOCK` has no effect on regular files).
#[cfg(target_os = "linux")]
fn open_nonblocking(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
}

#[cfg(not(target_os = "linux"))]
fn open_nonblocking(path: &Path) -> std::io::Result<std::fs::File> {
    std::fs::File::open(path)
}

fn too_large(what: &str, cap: u64, size: Option<u64>) -> std::io::Error {
    let size = size.map_or_else(|| "more than that".to_string(), |n| format!("{n} bytes"));
    std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!(
            "the {what} is larger than the limit of {cap} bytes ({}; it has {size}; see docs/limits.md)",
            human(cap)
        ),
    )
}

/// `33554432` → `32 MiB`.
fn human(n: u64) -> String {
    if n >= MIB && n.is_multiple_of(MIB) {
        format!("{} MiB", n / MIB)
    } else {
        format!("{n} B")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_file_within_cap_is_read_whole() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        std::fs::write(&p, b"0123456789").unwrap();
        assert_eq!(read_file(&p, "test file", 10).unwrap(), b"0123456789");
        assert_eq!(read_text(&p, "test file", 10).unwrap(), "0123456789");
    }

    #[test]
    fn one_byte_over_the_cap_is_refused_with_the_limit() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        std::fs::write(&p, b"01234567890").unwrap();
        let e = read_file(&p, "test file", 10).unwrap_err().to_string();
        assert!(e.contains("limit of 10 bytes"), "{e}");
        assert!(e.contains("11 bytes"), "{e}");
        assert!(e.contains("test file"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn devices_directories_and_fifos_are_refused_without_reading() {
        let e = read_file(Path::new("/dev/zero"), "list file", 10).unwrap_err();
        assert!(e.to_string().contains("a character device"), "{e}");
        let e = read_file(Path::new("/dev/urandom"), "list file", 10).unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let e = read_file(dir.path(), "list file", 10).unwrap_err();
        assert!(e.to_string().contains("a directory"), "{e}");
        // A FIFO with no writer: opening it for reading would block forever.
        let fifo = dir.path().join("fifo");
        let ok = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .is_ok_and(|s| s.success());
        if ok {
            let e = read_file(&fifo, "list file", 10).unwrap_err();
            assert!(e.to_string().contains("a FIFO"), "{e}");
        }
    }

    #[cfg(unix)]
    #[test]
    fn symlink_to_a_device_is_a_device() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("zero.lis");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        let e = read_file(&link, "list file", 10).unwrap_err();
        assert!(e.to_string().contains("a character device"), "{e}");
    }

    #[test]
    fn non_utf8_text_names_the_offset() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        std::fs::write(&p, b"ab\xffcd").unwrap();
        let e = read_text(&p, "machine file", 10).unwrap_err().to_string();
        assert!(e.contains("offset 2"), "{e}");
    }
}
