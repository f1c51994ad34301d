//! `fieldprobe sdo read|write`: one object by SDO, CoE on an EtherCAT SubDevice (`--device`)
//! or a CANopen node (`--node`).
//!
//! ```text
//! fieldprobe sdo read  [--link LINK] (--device N | --node N) INDEX[:SUB] [--type T]
//! fieldprobe sdo write [--link LINK] (--device N | --node N) INDEX[:SUB] VALUE [--type T]
//! ```
//! Numbers follow the CLI's one grammar ([`super::number`]): `--device 0x1`, `--node 0x03`,
//! `4104` = object 0x1008 (a note on stderr says so), `-12345` without `--`. `--type` is one of
//! [`super::value::TYPE_NAMES`]; values are encoded little-endian (CiA 301 §7.1.2), a value
//! outside the type's range is refused before anything is sent. Exit 0; 1 when the device
//! refuses the access (SDO abort, in words); 2 on bad input or a bus error.

use super::bus::{refused, Bus, SdoBusArgs};
use super::number::{self, show_object, ObjectRef};
use super::value::{count_bytes, show_bytes, show_string, ValueType, TYPE_NAMES};
use super::{EXIT_BAD_INPUT, EXIT_OK};

/// Arguments of `fieldprobe sdo`.
#[derive(Debug, clap::Args)]
pub struct SdoArgs {
    #[command(subcommand)]
    op: SdoOp,
}

#[derive(Debug, clap::Subcommand)]
enum SdoOp {
    /// Upload (read) an object.
    Read(SdoRead),
    /// Download (write) an object.
    Write(SdoWrite),
}

/// The bus and the device (EtherCAT) or node (CANopen) an SDO goes to.
#[derive(Debug, clap::Args)]
pub(super) struct SdoTo {
    #[command(flatten)]
    bus: SdoBusArgs,
    /// Ring position of the SubDevice, as `scan` prints it (EtherCAT links); decimal or 0x hex.
    #[arg(long, value_name = "N", required_unless_present = "node", conflicts_with = "node",
          value_parser = number::value_ring_position, allow_hyphen_values = true)]
    device: Option<usize>,
    /// CANopen node id 1 … 127 (CAN links); decimal or 0x hex.
    #[arg(long, value_name = "N", value_parser = number::value_node_id, allow_hyphen_values = true)]
    node: Option<u8>,
}

#[derive(Debug, clap::Args)]
struct SdoRead {
    #[command(flatten)]
    to: SdoTo,
    /// Object INDEX[:SUB] (sub-index 0 when left out), each decimal or 0x hex: `0x6041`,
    /// `0x1018:0x02`; an index without 0x is decimal (`4104` is 0x1008).
    object: String,
    /// Data type: u8 u16 u32 u64 i8 i16 i32 i64 f32 f64 bool string bytes (also IgH's uint8 …
    /// int64, float, double, octet_string and the CiA 301 names); default: the CiA 402 type
    /// of the object, else by length.
    #[arg(long = "type", value_name = "TYPE", value_parser = ValueType::parse_option)]
    ty: Option<ValueType>,
}

#[derive(Debug, clap::Args)]
struct SdoWrite {
    #[command(flatten)]
    to: SdoTo,
    /// Object INDEX[:SUB], as for `sdo read`.
    object: String,
    /// Value: an integer (decimal or 0x hex, negative without `--`), a decimal number for
    /// f32 / f64, the text for `string`, hex bytes (`01 02 0a`) for `bytes`.
    #[arg(allow_hyphen_values = true)]
    value: String,
    /// Data type, as for `sdo read`; default: the CiA 402 type of the object (required for
    /// other objects).
    #[arg(long = "type", value_name = "TYPE", value_parser = ValueType::parse_option)]
    ty: Option<ValueType>,
}

/// Whom an SDO goes to.
pub(super) enum Target {
    Device(usize),
    Node(u8),
}

impl std::fmt::Display for Target {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Target::Device(d) => write!(f, "device {d}"),
            Target::Node(n) => write!(f, "node {n}"),
        }
    }
}

/// The bus and the target, checked: the link first (an unknown link is named as such), then
/// that `--device` / `--node` fits it, and on `canopen-emu` that the node is emulated.
pub(super) fn target(to: &SdoTo, command: &str) -> anyhow::Result<(Bus, Target)> {
    let bus = to.bus.bus(command, to.node.is_some())?;
    let t = match (bus.link.is_can(), to.device, to.node) {
        (false, Some(d), None) => Target::Device(d),
        (true, None, Some(n)) => Target::Node(n),
        (true, _, _) => anyhow::bail!(
            "--link {}: a CAN link addresses nodes: give --node N (1 … 127), not --device",
            bus.text
        ),
        (false, _, _) => anyhow::bail!(
            "--link {}: an EtherCAT link addresses SubDevices: give --device N (ring position as `scan` prints it), not --node",
            bus.text
        ),
    };
    if let (Target::Node(n), Some(ids)) = (&t, bus.emulated_nodes()?) {
        if !ids.contains(n) {
            let list: Vec<String> = ids.iter().map(u8::to_string).collect();
            anyhow::bail!(
                "--node {n}: --link {} emulates node(s) {} (one per axis of the machine file)",
                bus.text,
                list.join(", ")
            );
        }
    }
    Ok((bus, t))
}

/// Parse the object and say on stderr how a decimal index was read.
fn object(text: &str) -> anyhow::Result<ObjectRef> {
    let o = number::object("object", text)?;
    for note in o.notes() {
        eprintln!("fieldprobe: note: {note}");
    }
    Ok(o)
}

/// `fieldprobe sdo`.
pub fn sdo(a: SdoArgs) -> anyhow::Result<i32> {
    match a.op {
        SdoOp::Read(r) => read(r),
        SdoOp::Write(w) => write(w),
    }
}

fn read(r: SdoRead) -> anyhow::Result<i32> {
    let o = object(&r.object)?;
    let (bus, target) = target(&r.to, "sdo")?;
    let result = match target {
        Target::Device(d) => {
            let mut s = bus.open()?;
            let res = s.sdo_read(d, o.index, o.sub);
            super::finish_capture(s.finish_capture());
            res
        }
        Target::Node(n) => {
            let mut s = bus.open_can()?;
            let res = s.sdo_upload(n, o.index, o.sub);
            super::finish_capture(s.finish_capture());
            res
        }
    };
    let bytes = match result {
        Ok(b) => b,
        Err(e) => return refused(e),
    };
    let shown = show_object(o.index, o.sub);
    let ty = r.ty.or_else(|| {
        let known = fieldprobe::drive::pdo::lookup(o.index, o.sub).map(|x| x.ty);
        known.map(ValueType::from_pdo).or(match bytes.len() {
            1 => Some(ValueType::U8),
            2 => Some(ValueType::U16),
            4 => Some(ValueType::U32),
            _ => None,
        })
    });
    match ty {
        Some(t) => match t.show(&bytes) {
            Some(v) => outln!("{shown} = {v}"),
            None => {
                eprintln!(
                    "fieldprobe: {target}, {shown}: the object has {} bytes, type {} has {}; its bytes: {}",
                    bytes.len(),
                    t.name(),
                    t.size().unwrap_or(0),
                    show_bytes(&bytes)
                );
                return Ok(EXIT_BAD_INPUT);
            }
        },
        // Unknown object of another length: text if it looks like text.
        None if !bytes.is_empty() && bytes.iter().all(|b| b.is_ascii_graphic() || *b == b' ') => {
            outln!("{shown} = {}", show_string(&bytes));
        }
        None => outln!("{shown} = {}", show_bytes(&bytes)),
    }
    Ok(EXIT_OK)
}

fn write(w: SdoWrite) -> anyhow::Result<i32> {
    let o = object(&w.object)?;
    let shown = show_object(o.index, o.sub);
    let ty = match w.ty {
        Some(t) => t,
        None => fieldprobe::drive::pdo::lookup(o.index, o.sub)
            .map(|x| ValueType::from_pdo(x.ty))
            .ok_or_else(|| anyhow::anyhow!("{shown}: type unknown; give --type ({TYPE_NAMES})"))?,
    };
    let data = ty.encode(&w.value).map_err(|expected| {
        // A number the type cannot hold, or no number (text) at all.
        let numeric = ty.size().is_some() && number::real(&w.value).is_some();
        let what = if numeric {
            "out of range for"
        } else {
            "not a value of"
        };
        let whose = match w.ty {
            Some(_) => format!("--type {}", ty.name()),
            None => format!("{} (the type of {shown})", ty.name()),
        };
        anyhow::anyhow!(
            "value {}: {what} {whose}: expected {expected}",
            super::cap_echo(&w.value)
        )
    })?;
    let (bus, target) = target(&w.to, "sdo")?;
    let result = match target {
        Target::Device(d) => {
            let mut s = bus.open()?;
            let res = s.sdo_write(d, o.index, o.sub, &data);
            super::finish_capture(s.finish_capture());
            res
        }
        Target::Node(n) => {
            let mut s = bus.open_can()?;
            let res = s.sdo_download(n, o.index, o.sub, &data);
            super::finish_capture(s.finish_capture());
            res
        }
    };
    match result {
        Ok(()) => {
            outln!("{shown} written ({})", count_bytes(data.len()));
            Ok(EXIT_OK)
        }
        Err(e) => refused(e),
    }
}
