//! `fieldprobe esi`: read EtherCAT Slave Information (ETG.2000 XML) files.
//!
//! ```text
//! fieldprobe esi show FILE.xml [--device PRODUCT_CODE] [--objects]
//! ```
//! Prints the vendor and, per device, its identity, sync managers, FMMUs, PDOs with their
//! entries, mailbox protocols, DC op modes and the number of dictionary objects (`--objects`:
//! the object list). Exit 0; 2 on bad input, with the parser's error
//! (`file:line:column: element path: problem`) on stderr.

use super::EXIT_OK;
use fieldprobe::esi::{self, Access, Device, Pdo, SmKind};
use std::path::PathBuf;

/// Arguments of `fieldprobe esi`.
#[derive(Debug, clap::Args)]
pub struct EsiArgs {
    #[command(subcommand)]
    command: EsiCommand,
}

#[derive(Debug, clap::Subcommand)]
enum EsiCommand {
    /// Show the devices of an ESI file: identity, sync managers, PDOs, mailbox, DC, objects.
    Show(ShowArgs),
}

/// Arguments of `fieldprobe esi show`.
#[derive(Debug, clap::Args)]
struct ShowArgs {
    /// The ESI file (EtherCATInfo XML).
    file: PathBuf,
    /// Only the device with this product code (`0x10402`, `#x10402` or decimal).
    #[arg(long, value_name = "PRODUCT_CODE", value_parser = parse_number)]
    device: Option<u32>,
    /// List the dictionary objects (index, name, type, access, default).
    #[arg(long)]
    objects: bool,
}

/// `0x…` / `#x…` hexadecimal or decimal.
fn parse_number(s: &str) -> Result<u32, String> {
    let t = s.trim();
    let r = if let Some(h) = t
        .strip_prefix("0x")
        .or_else(|| t.strip_prefix("0X"))
        .or_else(|| t.strip_prefix("#x"))
    {
        u32::from_str_radix(h, 16)
    } else {
        t.parse()
    };
    r.map_err(|_| format!("not a number: {s:?} (expected 0x hex, #x hex or decimal)"))
}

/// Run the command; returns the exit code.
pub fn run(a: EsiArgs) -> anyhow::Result<i32> {
    match a.command {
        EsiCommand::Show(s) => show(s),
    }
}

fn show(a: ShowArgs) -> anyhow::Result<i32> {
    let file = esi::load(&a.file)?;
    let devices: Vec<&Device> = match a.device {
        Some(code) => {
            let found: Vec<&Device> = file
                .devices
                .iter()
                .filter(|d| d.product_code == code)
                .collect();
            if found.is_empty() {
                let have: Vec<String> = file
                    .devices
                    .iter()
                    .map(|d| format!("0x{:08X} ({})", d.product_code, d.type_name))
                    .collect();
                anyhow::bail!(
                    "{}: no device with product code 0x{code:08X}; the file has: {}",
                    file.file,
                    if have.is_empty() {
                        "no devices".to_string()
                    } else {
                        have.join(", ")
                    }
                );
            }
            found
        }
        None => file.devices.iter().collect(),
    };
    outln!("file: {}", file.file);
    outln!("vendor: 0x{:08X} {}", file.vendor.id, file.vendor.name);
    outln!("devices: {}", file.devices.len());
    for d in devices {
        show_device(file.vendor.id, d, a.objects);
    }
    Ok(EXIT_OK)
}

fn show_device(vendor: u32, d: &Device, objects: bool) {
    outln!();
    outln!("device {}: {}", d.type_name, d.name());
    outln!(
        "  identity: vendor 0x{vendor:08X}, product code 0x{:08X}, revision 0x{:08X}",
        d.product_code,
        d.revision_no
    );
    if let Some(g) = &d.group {
        outln!("  group: {g}");
    }
    if let Some(p) = &d.physics {
        outln!("  physics: {p}");
    }
    outln!("  mailbox: {}", mailbox(d));
    if !d.fmmus.is_empty() {
        let f: Vec<String> = d
            .fmmus
            .iter()
            .map(|f| match f {
                esi::FmmuKind::Outputs => "Outputs".to_string(),
                esi::FmmuKind::Inputs => "Inputs".to_string(),
                esi::FmmuKind::MBoxState => "MBoxState".to_string(),
                esi::FmmuKind::Other(s) => format!("{s:?}"),
            })
            .collect();
        outln!("  fmmus: {}", f.join(", "));
    }
    outln!("  sync managers: {}", d.sync_managers.len());
    for (i, sm) in d.sync_managers.iter().enumerate() {
        let kind = match &sm.kind {
            SmKind::MBoxOut => "MBoxOut".to_string(),
            SmKind::MBoxIn => "MBoxIn".to_string(),
            SmKind::Outputs => "Outputs".to_string(),
            SmKind::Inputs => "Inputs".to_string(),
            SmKind::Other(s) => format!("{s:?}"),
        };
        let size = sm
            .default_size
            .map_or_else(|| "-".to_string(), |s| s.to_string());
        outln!(
            "    SM{i} {kind}: start 0x{:04X}, default size {size}, control 0x{:02X}, {}",
            sm.start_address,
            sm.control_byte,
            if sm.enable { "enabled" } else { "disabled" }
        );
    }
    for p in &d.rx_pdos {
        show_pdo("RxPDO", p);
    }
    for p in &d.tx_pdos {
        show_pdo("TxPDO", p);
    }
    if !d.dc_op_modes.is_empty() {
        outln!("  DC op modes: {}", d.dc_op_modes.len());
        for m in &d.dc_op_modes {
            let mut line = format!(
                "    {}: assign activate 0x{:04X}",
                m.name, m.assign_activate
            );
            for (label, t) in [
                ("cycle SYNC0", m.cycle_time_sync0),
                ("shift SYNC0", m.shift_time_sync0),
                ("cycle SYNC1", m.cycle_time_sync1),
                ("shift SYNC1", m.shift_time_sync1),
            ] {
                if let Some(t) = t {
                    line.push_str(&format!(", {label} {} ns", t.value));
                    if let Some(f) = t.factor {
                        line.push_str(&format!(" (factor {f})"));
                    }
                }
            }
            if let Some(desc) = &m.desc {
                line.push_str(&format!(" ({desc})"));
            }
            outln!("{line}");
        }
    }
    if let Some(e) = &d.eeprom {
        if let Some(b) = e.byte_size {
            outln!("  eeprom: {b} bytes");
        }
    }
    let dict = d.dictionary();
    let count = dict.map_or(0, |dict| dict.objects.len());
    outln!("  objects: {count}");
    if objects {
        if let Some(dict) = dict {
            for o in &dict.objects {
                let access = match o.flags.access {
                    Some(Access::ReadOnly) => "ro",
                    Some(Access::ReadWrite) => "rw",
                    Some(Access::WriteOnly) => "wo",
                    None => "-",
                };
                let default = match (&o.default_data, o.default_u64()) {
                    (Some(b), Some(v)) if b.len() <= 8 => format!("{v}"),
                    (Some(b), _) => b.iter().map(|x| format!("{x:02X}")).collect(),
                    (None, _) => "-".to_string(),
                };
                outln!(
                    "    0x{:04X} {}: {}, {access}, default {default}",
                    o.index,
                    o.name,
                    o.type_name
                );
            }
        }
    }
}

fn mailbox(d: &Device) -> String {
    let Some(mb) = &d.mailbox else {
        return "none".to_string();
    };
    let mut protos = Vec::new();
    if let Some(coe) = &mb.coe {
        let mut details = Vec::new();
        for (on, name) in [
            (coe.sdo_info, "SdoInfo"),
            (coe.pdo_assign, "PdoAssign"),
            (coe.pdo_config, "PdoConfig"),
            (coe.pdo_upload, "PdoUpload"),
            (coe.complete_access, "CompleteAccess"),
            (coe.segmented_sdo, "SegmentedSdo"),
        ] {
            if on {
                details.push(name);
            }
        }
        if details.is_empty() {
            protos.push("CoE".to_string());
        } else {
            protos.push(format!("CoE ({})", details.join(", ")));
        }
    }
    for (on, name) in [
        (mb.soe, "SoE"),
        (mb.eoe, "EoE"),
        (mb.foe, "FoE"),
        (mb.aoe, "AoE"),
        (mb.voe, "VoE"),
    ] {
        if on {
            protos.push(name.to_string());
        }
    }
    if protos.is_empty() {
        protos.push("no protocols".to_string());
    }
    let mut s = protos.join(", ");
    if mb.data_link_layer {
        s.push_str("; data link layer");
    }
    s
}

fn show_pdo(kind: &str, p: &Pdo) {
    let mut attrs = vec![match p.sm {
        Some(sm) => format!("SM{sm}"),
        None => "not assigned".to_string(),
    }];
    attrs.push(format!("{} bits", p.bit_len()));
    if p.fixed {
        attrs.push("fixed".to_string());
    }
    if p.mandatory {
        attrs.push("mandatory".to_string());
    }
    if !p.excludes.is_empty() {
        let ex: Vec<String> = p.excludes.iter().map(|x| format!("0x{x:04X}")).collect();
        attrs.push(format!("excludes {}", ex.join(" ")));
    }
    outln!(
        "  {kind} 0x{:04X} {}: {}",
        p.index,
        if p.name.is_empty() { "-" } else { &p.name },
        attrs.join(", ")
    );
    for e in &p.entries {
        let name = if e.index == 0 {
            "(gap)"
        } else {
            e.name.as_deref().unwrap_or("-")
        };
        let ty = e
            .data_type
            .as_deref()
            .map(|t| format!(" ({t})"))
            .unwrap_or_default();
        outln!(
            "    0x{:04X}:{:02X} {:>2} bits {name}{ty}",
            e.index,
            e.subindex,
            e.bit_len
        );
    }
}
