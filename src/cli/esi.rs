//! `fieldprobe esi`: read EtherCAT Slave Information (ETG.2000 XML) files.
//!
//! ```text
//! fieldprobe esi list FILE.xml
//! fieldprobe esi show FILE.xml[#SEL] [--device SEL] [--objects]
//! ```
//! `list` prints one line per device: position, type name, product code, revision, profiles,
//! slots and modules, name. `show` prints the vendor and, per device, its identity, profiles,
//! 0x1000, sync managers, FMMUs, PDOs with their entries, mailbox protocols, DC op modes and the
//! number of dictionary objects (`--objects`: the object list): every device of the file, or
//! the one SEL names ([`fieldprobe::esi::select`]), resolved with its modules. The reader's
//! warnings go to stderr as `warning: …`. Exit 0; 2 on bad input, with the parser's error
//! (`file:line:column: element path: problem`) on stderr.

use super::esi_load;
use super::EXIT_OK;
use fieldprobe::esi::{self, Access, Device, Pdo, SmKind};

/// Arguments of `fieldprobe esi`.
#[derive(Debug, clap::Args)]
pub struct EsiArgs {
    #[command(subcommand)]
    command: EsiCommand,
}

#[derive(Debug, clap::Subcommand)]
enum EsiCommand {
    /// One line per device of an ESI file: @N position, type, product code, revision,
    /// profiles, slots and modules, name. @N, the type name or PRODUCT/REVISION select a
    /// device in every command (FILE.xml#SEL).
    List(ListArgs),
    /// Show the devices of an ESI file: identity, sync managers, PDOs, mailbox, DC, objects.
    Show(ShowArgs),
}

/// Arguments of `fieldprobe esi list`.
#[derive(Debug, clap::Args)]
struct ListArgs {
    /// The ESI file (EtherCATInfo XML).
    file: String,
}

/// Arguments of `fieldprobe esi show`.
#[derive(Debug, clap::Args)]
struct ShowArgs {
    /// The ESI file (EtherCATInfo XML), optionally `#SEL` to show one device resolved with its
    /// modules (SEL: TYPE[/REVISION], PRODUCT_CODE[/REVISION] or @N, then +MODULE per slot).
    #[arg(value_name = "FILE.xml[#SEL]")]
    file: String,
    /// Only this device (the SEL of FILE.xml#SEL, e.g. a product code `0x10402`).
    #[arg(long, value_name = "SEL")]
    device: Option<String>,
    /// List the dictionary objects (index, name, type, access, default).
    #[arg(long)]
    objects: bool,
}

/// Run the command; returns the exit code.
pub fn run(a: EsiArgs) -> anyhow::Result<i32> {
    match a.command {
        EsiCommand::List(l) => list(l),
        EsiCommand::Show(s) => show(s),
    }
}

fn list(a: ListArgs) -> anyhow::Result<i32> {
    let (path, sel) = esi_load::split(&a.file);
    anyhow::ensure!(
        sel.is_none(),
        "esi list takes a file without #SEL (it lists every device)"
    );
    let file = esi_load::load(&path)?;
    for (i, d) in file.devices.iter().enumerate() {
        outln!("{}", list_line(i + 1, d));
    }
    Ok(EXIT_OK)
}

/// `@3 EJ7211-0010 0x1C2B2852/0x001A000A profiles 5001:513,5001:742 slots - "name"`.
fn list_line(position: usize, d: &Device) -> String {
    format!(
        "@{position} {} 0x{:08X}/0x{:08X} profiles {} slots {} {:?}",
        if d.type_name.is_empty() {
            "-"
        } else {
            &d.type_name
        },
        d.product_code,
        d.revision_no,
        profiles(d),
        slots(d),
        d.name()
    )
}

/// `402`, `5001:513,5001:742` (profile number, `:AddInfo` where given), `-` for none.
fn profiles(d: &Device) -> String {
    let v: Vec<String> = d
        .profile_infos()
        .iter()
        .map(|(n, add)| match add {
            Some(a) => format!("{n}:{a}"),
            None => n.to_string(),
        })
        .collect();
    if v.is_empty() {
        "-".to_string()
    } else {
        v.join(",")
    }
}

/// `-`, or per slot `NAME[min..max]=DEFAULT(choices)`: `Axis 0[1..1]=#x119800(3 modules)`.
fn slots(d: &Device) -> String {
    let Some(slots) = &d.slots else {
        return "-".to_string();
    };
    let v: Vec<String> = slots
        .slots
        .iter()
        .map(|s| {
            let def = s
                .modules
                .iter()
                .find(|m| m.default)
                .map_or_else(|| "none".to_string(), |m| format!("#x{:X}", m.ident));
            format!(
                "{:?}[{}..{}]={def}({} modules)",
                s.name,
                s.min_instances,
                s.max_instances,
                s.modules.len() + s.classes.len()
            )
        })
        .collect();
    v.join(";")
}

fn show(a: ShowArgs) -> anyhow::Result<i32> {
    let (path, sel) = esi_load::split(&a.file);
    let file = esi_load::load(&path)?;
    let sel = esi_load::selector(sel.as_deref(), a.device.as_deref())?;
    let chosen = sel
        .map(|sel| esi_load::choose(&file, Some(&sel)))
        .transpose()?;
    outln!("file: {}", file.file);
    outln!("vendor: 0x{:08X} {}", file.vendor.id, file.vendor.name);
    outln!("devices: {}", file.devices.len());
    match &chosen {
        Some(r) => show_device(file.vendor.id, r, a.objects),
        None => {
            for d in &file.devices {
                show_device(file.vendor.id, d, a.objects);
            }
        }
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
    outln!("  profiles: {}", profiles(d));
    for c in d.channels() {
        let add = c
            .add_info
            .map(|a| format!(" AddInfo {a}"))
            .unwrap_or_default();
        let name = c
            .display_name
            .as_deref()
            .map(|n| format!(" {n}"))
            .unwrap_or_default();
        outln!("    channel: ProfileNo {}{add}{name}", c.profile_no);
    }
    if let Some(t) = d.device_type() {
        outln!("  device type (0x1000): 0x{t:08X}");
    }
    if let Some(s) = &d.slots {
        outln!(
            "  slots: {} (SlotIndexIncrement #x{:X}, SlotPdoIncrement {})",
            self::slots(d),
            s.slot_index_increment,
            s.slot_pdo_increment
        );
        for m in &d.modules {
            outln!("    module #x{:X}: {}", m.ident, m.type_name);
        }
    }
    if let Some(plugged) = &d.plugged {
        for p in plugged {
            outln!(
                "  slot {} ({}): module #x{:X} {}",
                p.slot,
                p.slot_name,
                p.ident,
                p.type_name
            );
        }
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
