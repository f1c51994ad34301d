//! Drive definitions (`drives/*.toml`, [`super::catalogue`]) written from a vendor's device
//! description: an EtherCAT ESI (ETG.2000 `Dictionary`, `Flags/PdoMapping`) or a CANopen EDS
//! (CiA 306 `PDOMapping`, `AccessType`). `fieldprobe drive from-esi` / `drive from-eds`.
//!
//! The vendor file is first reduced to a [`VendorDevice`] — identity plus the CiA 402 objects
//! this module looks at, each with its data type, access and PDO direction as the file states
//! them (`VendorDevice::from_esi` with feature `ethercat`, `VendorDevice::from_eds` with feature
//! `canopen`); [`generate`] then writes the
//! definition:
//!
//! * `[rxpdo]` / `[txpdo]`: the objects a CiA 402 axis in CSP needs (0x6040, 0x607A, 0x6060
//!   out; 0x6041, 0x6064, 0x6061 in) — each must exist, be mappable in its direction and have
//!   CiA 402's size, otherwise [`VendorError::MissingObjects`] names them all; then the optional
//!   ones where the device offers them the same way: following error 0x60F4, torque actual
//!   0x6077 and the touch probe (0x60B8 out, 0x60B9 … 0x60BD in; CiA 402 §4.8, seed 004 §6.4).
//!   An optional object left out is a comment in the file and a [`Generated::notes`] line.
//! * `[scaling]`: a placeholder marked `TO FILL`; the comment quotes the position factor group
//!   (0x608F encoder resolution, 0x6091 gear ratio, 0x6092 feed constant) where the file has
//!   their defaults — the millimetres per revolution are the machine's, not the drive's.
//! * `[functions]` (seed 004 §7.3.2): TORQUE_LIMIT → 0x6072, TORQUE_LIMIT_POS / _NEG → 0x60E0 /
//!   0x60E1, MON_WINDOW → 0x6065, MON_TIMEOUT → 0x6066, for each writable object the device
//!   has, typed as the file types it, limits from the file where it gives them (EDS
//!   `LowLimit` / `HighLimit`); the `[idn]` mappings S-0-0092 / S-0-0159 of seed 004 §7.3.1
//!   follow the objects they name.
//! * `[probe]` only for a device with a touch probe.
//!
//! The result is parsed by [`super::catalogue::parse`] before it is returned, so what this
//! module writes is what the catalogue accepts.

use super::catalogue;
use super::pdo::{self, DataType};
use std::fmt::Write as _;

/// One object (index, sub-index) of the vendor's dictionary, as the file states it.
#[derive(Debug, Clone, PartialEq)]
pub struct VendorObject {
    /// Index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// The CiA 402 object it is, or plays (a modular device profile object such as the
    /// "Following error window" 0x8010:50 of a Beckhoff servo terminal); `(index, sub)` for the
    /// CiA 402 object itself.
    pub plays: (u16, u8),
    /// Name in the file.
    pub name: String,
    /// Data type name as written (`UINT`, `UNSIGNED16`).
    pub type_name: String,
    /// The type as fieldprobe maps it; `None` for a type no drive file can hold (REAL32,
    /// 64-bit, strings).
    pub ty: Option<DataType>,
    /// Size in bits.
    pub bits: u32,
    /// May be mapped into an RxPDO (master → device).
    pub rx: bool,
    /// May be mapped into a TxPDO (device → master).
    pub tx: bool,
    /// May be written by SDO.
    pub writable: bool,
    /// Default value, if the file gives one that is a number.
    pub default: Option<i64>,
    /// Smallest value, if the file gives one.
    pub low: Option<i64>,
    /// Largest value, if the file gives one.
    pub high: Option<i64>,
}

/// A vendor device reduced to what [`generate`] needs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct VendorDevice {
    /// The file the device came from, as given.
    pub file: String,
    /// `ESI` or `EDS`.
    pub kind: &'static str,
    /// Vendor name.
    pub vendor: String,
    /// Vendor id (EtherCAT vendor ID / CiA 301 0x1018:01).
    pub vendor_id: Option<u32>,
    /// Product (ESI `Type` / EDS `ProductName`).
    pub product: String,
    /// Product code (0x1018:02).
    pub product_code: Option<u32>,
    /// Revision (0x1018:03).
    pub revision: Option<u32>,
    /// Objects of the dictionary this module reads ([`OBJECTS_READ`]), those present.
    pub objects: Vec<VendorObject>,
    /// Roles and PDOs chosen from the device's own PDO descriptions (an ESI device:
    /// `esi_plan::plan`); `None`: the CiA 402 objects the file marks mappable are mapped into
    /// the first PDO of each direction.
    pub plan: Option<plan::Plan>,
    /// Why no plan could be made (the required roles the device cannot carry).
    pub plan_error: Option<plan::PlanError>,
    /// The device as a reference to its file (`FILE.xml#@N+MODULE…`, modules included), for
    /// `[device] esi`; `None`: [`Self::file`].
    pub reference: Option<String>,
}

impl VendorDevice {
    /// The object `index:sub`, if the file has it.
    pub fn object(&self, index: u16, sub: u8) -> Option<&VendorObject> {
        self.objects.iter().find(|o| o.plays == (index, sub))
    }
}

/// Objects [`generate`] reads: the PDO objects, the drive functions and the factor group
/// (0x608F / 0x6091 / 0x6092, subs 1 and 2).
pub const OBJECTS_READ: &[(u16, u8)] = &[
    (0x6040, 0),
    (0x607A, 0),
    (0x6060, 0),
    (0x6041, 0),
    (0x6064, 0),
    (0x6061, 0),
    (0x60F4, 0),
    (0x6077, 0),
    (0x60B8, 0),
    (0x60B9, 0),
    (0x60BA, 0),
    (0x60BB, 0),
    (0x60BC, 0),
    (0x60BD, 0),
    (0x6072, 0),
    (0x60E0, 0),
    (0x60E1, 0),
    (0x6065, 0),
    (0x6066, 0),
    (0x608F, 1),
    (0x608F, 2),
    (0x6091, 1),
    (0x6091, 2),
    (0x6092, 1),
    (0x6092, 2),
];

/// Why no definition could be written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VendorError {
    /// Objects a CiA 402 axis needs are missing or not mappable the way it needs them.
    #[error("{file}: device {product} cannot run a CiA 402 axis in cyclic synchronous position mode: {}", .missing.join("; "))]
    MissingObjects {
        /// The vendor file.
        file: String,
        /// The device.
        product: String,
        /// One phrase per object (`0x607A:00 target position: not in the file`).
        missing: Vec<String>,
    },
    /// The generated text did not pass the catalogue (a fault of this module; reported, not
    /// hidden).
    #[error("{file}: the generated drive definition is not accepted: {message}")]
    Internal {
        /// The vendor file.
        file: String,
        /// The catalogue's error.
        message: String,
    },
}

/// A written definition.
#[derive(Debug, Clone, PartialEq)]
pub struct Generated {
    /// The TOML text.
    pub toml: String,
    /// What was left out or needs the user's attention, one line each (for stderr).
    pub notes: Vec<String>,
    /// The device has a touch probe (a `[probe]` section was written).
    pub touch_probe: bool,
}

/// One PDO object the generator considers.
struct Wanted {
    index: u16,
    rx: bool,
    required: bool,
}

const fn want(index: u16, rx: bool, required: bool) -> Wanted {
    Wanted {
        index,
        rx,
        required,
    }
}

/// The axis objects, in the order they are mapped (the generic drive's order); the touch probe
/// objects follow, then [`TORQUE_ACTUAL`].
const AXIS_PDO: [Wanted; 7] = [
    want(0x6040, true, true),
    want(0x607A, true, true),
    want(0x6060, true, true),
    want(0x6041, false, true),
    want(0x6064, false, true),
    want(0x60F4, false, false),
    want(0x6061, false, true),
];

/// Torque actual value, mapped last (as in the generic drive).
const TORQUE_ACTUAL: Wanted = want(0x6077, false, false);

/// Touch probe objects: function (out), status and the four edge values (in).
const PROBE_PDO: [Wanted; 6] = [
    want(0x60B8, true, false),
    want(0x60B9, false, false),
    want(0x60BA, false, false),
    want(0x60BB, false, false),
    want(0x60BC, false, false),
    want(0x60BD, false, false),
];

/// A drive name from vendor and product: lower case, `-` between words (`ingenia-evs-net-01`).
pub fn drive_name(vendor: &str, product: &str) -> String {
    let mut out = String::new();
    let first = vendor.split_whitespace().next().unwrap_or("");
    let text = if product
        .to_ascii_lowercase()
        .starts_with(&first.to_ascii_lowercase())
    {
        product.to_string()
    } else {
        format!("{first} {product}")
    };
    for c in text.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.is_empty() && !out.ends_with('-') {
            out.push('-');
        }
    }
    let name = out.trim_end_matches('-').to_string();
    if name.is_empty() {
        "vendor-drive".into()
    } else {
        name
    }
}

/// Is `o` usable as PDO entry `w`? `Err` says why not.
fn pdo_fit(o: Option<&VendorObject>, w: &Wanted, kind: &str) -> Result<(), String> {
    let Some(o) = o else {
        return Err("not in the file".into());
    };
    let dir_ok = if w.rx { o.rx } else { o.tx };
    if !dir_ok {
        let flag = if kind == "ESI" {
            "Flags/PdoMapping"
        } else {
            "PDOMapping / AccessType"
        };
        let dir = if w.rx { "an RxPDO" } else { "a TxPDO" };
        return Err(format!("not mappable into {dir} ({flag})"));
    }
    let cia = pdo::lookup(w.index, 0).map(|i| i.ty);
    if let Some(cia) = cia {
        if o.bits != cia.size() as u32 * 8 {
            return Err(format!(
                "{} bits ({}) where CiA 402 has {cia}",
                o.bits, o.type_name
            ));
        }
    }
    Ok(())
}

fn cia_name(index: u16) -> &'static str {
    pdo::lookup(index, 0).map_or("object", |i| i.name)
}

fn hex_opt(v: Option<u32>) -> String {
    v.map_or_else(|| "not given".into(), |v| format!("0x{v:08X}"))
}

/// Write the drive definition for `dev`; `name` overrides the generated drive name.
///
/// # Errors
/// [`VendorError::MissingObjects`] naming every required object that is missing, not mappable
/// in its direction or of the wrong size.
pub fn generate(dev: &VendorDevice, name: Option<&str>) -> Result<Generated, VendorError> {
    generate_in(dev, name, None)
}

/// [`generate`] for a device whose PDOs `pdos` are known (a CANopen device by its EDS,
/// `drive from-eds`; issue 25): the entries are fitted into them ([`capacity`]: optional
/// objects leave where there is no room, 0x6060 may go by SDO) and the file says what the
/// device offers.
///
/// # Errors
/// As [`generate`]; also when the objects a CSP axis needs find no room in `pdos`.
pub fn generate_in(
    dev: &VendorDevice,
    name: Option<&str>,
    pdos: Option<&PdoCapacity>,
) -> Result<Generated, VendorError> {
    let kind = dev.kind;
    if let Some(e) = &dev.plan_error {
        return Err(VendorError::MissingObjects {
            file: dev.file.clone(),
            product: dev.product.clone(),
            missing: e.missing.clone(),
        });
    }
    let Sections {
        pdo_text,
        touch_probe,
        mut notes,
    } = match &dev.plan {
        Some(plan) => planned_sections(dev, plan),
        None => listed_sections(dev, pdos)?,
    };
    let name = name
        .map(str::to_string)
        .unwrap_or_else(|| drive_name(&dev.vendor, &dev.product));
    let mut t = String::new();
    let file_name = std::path::Path::new(&dev.file)
        .file_name()
        .map_or(dev.file.clone(), |f| f.to_string_lossy().into_owned());
    let _ = writeln!(
        t,
        "# CiA 402 drive in cyclic synchronous position mode (CSP), written by `fieldprobe drive \
         from-{}`",
        kind.to_ascii_lowercase()
    );
    let _ = writeln!(
        t,
        "# from the vendor's {kind} file {}:",
        one_line(&file_name)
    );
    let _ = writeln!(
        t,
        "#   vendor   {} (vendor id {})",
        one_line(&dev.vendor),
        hex_opt(dev.vendor_id)
    );
    let _ = writeln!(
        t,
        "#   product  {}, product code {}, revision {}",
        one_line(&dev.product),
        hex_opt(dev.product_code),
        hex_opt(dev.revision)
    );
    let _ = writeln!(
        t,
        "# PDO entries: the CiA 402 objects the device marks mappable in their direction\n\
         # ({}).\n# Review every value marked TO FILL before the drive moves a machine.",
        if kind == "ESI" {
            "Flags/PdoMapping R, T or RT"
        } else {
            "PDOMapping=1; AccessType rww / rw / wo out, ro / rwr / rw / const in"
        }
    );
    if let Some(cap) = pdos {
        let _ = writeln!(
            t,
            "# PDOs 1 … 4 (the predefined connection set the master maps) the file gives the\n\
             # device: {}, {}; the entries below fit them\n\
             # (the master asks the node for its PDOs at start-up and fits its mapping then).",
            cap.describe(true),
            cap.describe(false)
        );
    }
    if !touch_probe {
        let _ = writeln!(
            t,
            "#\n# No touch probe (0x60B8 … 0x60BD): this axis has no drive latch. Measure with\n\
             # kenngr.measure.signal PLC (probe input read by the PLC, seed 004 §7.1),\n\
             # PLC_TIMESTAMP (a timestamp input terminal such as an EL1252, §7.5) or\n\
             # PLC_EXT_LATCH_CONTROL (external measuring hardware, §7.4)."
        );
    }
    let _ = writeln!(
        t,
        "\n[drive]\nname = \"{}\"\nprofile = \"cia402\"\n",
        toml_escape(&name)
    );

    // Scaling.
    let _ = writeln!(t, "[scaling]");
    let _ = writeln!(
        t,
        "# TO FILL: drive position increments (the unit of 0x607A / 0x6064) per mm of axis travel\n\
         # (per degree on a rotary axis) = encoder increments per motor revolution x motor\n\
         # revolutions per driving-shaft revolution / mm per shaft revolution (screw pitch)."
    );
    let factor = |index: u16, sub: u8| dev.object(index, sub).and_then(|o| o.default);
    let group = [
        (
            0x608F,
            "position encoder resolution",
            "increments",
            "motor revolutions",
        ),
        (
            0x6091,
            "gear ratio",
            "motor revolutions",
            "shaft revolutions",
        ),
        (0x6092, "feed constant", "feed", "shaft revolutions"),
    ];
    let mut any_factor = false;
    for (index, what, a, b) in group {
        if let (Some(n), Some(d)) = (factor(index, 1), factor(index, 2)) {
            any_factor = true;
            let _ = writeln!(
                t,
                "# The file's default 0x{index:04X} {what}: {n} {a} / {d} {b}."
            );
        }
    }
    if any_factor {
        let _ = writeln!(
            t,
            "# These are factory defaults of the drive's factor group, which scales 0x607A / 0x6064;\n\
             # read the values set in your drive and the mechanics of your axis."
        );
    } else {
        let _ = writeln!(
            t,
            "# The file gives no position factor group (0x608F / 0x6091 / 0x6092) defaults."
        );
    }
    let _ = writeln!(
        t,
        "# 10000 is a placeholder (0.1 um per increment), not a property of this drive.\n\
         increments_per_unit = 10000   # TO FILL\n\
         offset = 0.0                  # axis position at increment 0 (mm)\n"
    );

    t.push_str(&pdo_text);

    if touch_probe {
        let _ = writeln!(
            t,
            "[probe]\n\
             # TO CHECK in the drive manual: does the drive re-arm a touch probe only after 0x60B8\n\
             # went to 0 (then true)? 100 cycles is the time the adapter waits for 0x60B9.\n\
             rearm_requires_zero = false\n\
             arm_timeout_cycles = 100\n"
        );
    }

    // Drive functions.
    let functions = [
        ("TORQUE_LIMIT", 0x6072u16, "0.1 %", 10.0),
        ("TORQUE_LIMIT_POS", 0x60E0, "0.1 %", 10.0),
        ("TORQUE_LIMIT_NEG", 0x60E1, "0.1 %", 10.0),
        ("MON_WINDOW", 0x6065, "increments", 1.0),
        ("MON_TIMEOUT", 0x6066, "ms", 1.0),
    ];
    let mut written: Vec<(&str, (u16, u8), DataType)> = Vec::new();
    let mut fn_lines = String::new();
    for (key, index, unit, scale) in functions {
        let Some(o) = dev.object(index, 0) else {
            let _ = writeln!(
                fn_lines,
                "# {key}: 0x{index:04X} {} is not in the file.",
                cia_name(index)
            );
            continue;
        };
        let Some(ty) = o.ty else {
            notes.push(format!(
                "{key} left out: 0x{index:04X} {} has type {}, which a drive file cannot hold",
                o.name, o.type_name
            ));
            let _ = writeln!(
                fn_lines,
                "# {key}: 0x{index:04X} has type {}, not supported.",
                o.type_name
            );
            continue;
        };
        if !o.writable {
            notes.push(format!(
                "{key} left out: 0x{index:04X} {} is read-only in the file",
                o.name
            ));
            let _ = writeln!(fn_lines, "# {key}: 0x{index:04X} is read-only.");
            continue;
        }
        let (lo, hi) = ty.range();
        // Torque limits and monitoring values are not negative (CiA 402 §6.9, §11.3).
        let min = o.low.unwrap_or(0).clamp(lo.max(0), hi);
        let max = o.high.unwrap_or(hi).clamp(min, hi);
        let scale_text = if scale == 1.0 {
            String::new()
        } else {
            format!(", scale = {scale:.1}")
        };
        let _ = writeln!(
            fn_lines,
            "{key} = {{ object = \"0x{:04X}:{:02X}\", type = \"{}\", unit = \"{unit}\"{scale_text}, min = {min}, max = {max} }}",
            o.index,
            o.sub,
            ty.name()
        );
        written.push((key, (o.index, o.sub), ty));
    }
    let _ = writeln!(
        t,
        "[functions]\n\
         # drive function table (seed 004 §7.3.2): KEY -> object, type as the file gives it;\n\
         # values are written as round(value * scale) within [min, max] (wire units). Torque limits\n\
         # in % of rated torque (wire 0.1 %), the following error window in increments, its time\n\
         # out in ms."
    );
    t.push_str(&fn_lines);
    let idn: Vec<String> = written
        .iter()
        .filter_map(|&(key, (index, sub), ty)| match key {
            "TORQUE_LIMIT" => Some(format!(
                "\"S-0-0092\" = {{ object = \"0x{index:04X}:{sub:02X}\", type = \"{}\" }}",
                ty.name()
            )),
            "MON_WINDOW" if ty == DataType::U32 => Some(format!(
                "\"S-0-0159\" = {{ object = \"0x{index:04X}:{sub:02X}\", type = \"u32\", zero = 4294967295 }}"
            )),
            _ => None,
        })
        .collect();
    if !idn.is_empty() {
        let _ = writeln!(
            t,
            "\n[idn]\n# SERCOS IDNs of seed 004 §7.3.1 on this drive's objects (S-0-0092 torque limit,\n\
             # S-0-0159 monitoring window; SERCOS 0 = off = CiA 402 0xFFFFFFFF)."
        );
        for l in idn {
            let _ = writeln!(t, "{l}");
        }
    }

    catalogue::parse(&t, &format!("{name}.toml")).map_err(|e| VendorError::Internal {
        file: dev.file.clone(),
        message: e.to_string(),
    })?;
    Ok(Generated {
        toml: t,
        notes,
        touch_probe,
    })
}

/// The PDO sections of a definition and what goes with them.
struct Sections {
    /// `[device]`, `[roles]`, `[rxpdo]`, `[txpdo]` as TOML text.
    pdo_text: String,
    /// The device has a touch probe.
    touch_probe: bool,
    /// Notes for stderr.
    notes: Vec<String>,
}

/// The PDO sections from an ESI device's [`plan::Plan`]: `[device]`, `[roles]`, `[rxpdo]` /
/// `[txpdo]` with the PDOs chosen, their entries (gaps and bit fields as the PDOs hold them),
/// and `defaults` for the outputs of a fixed PDO that are not roles.
fn planned_sections(dev: &VendorDevice, plan: &plan::Plan) -> Sections {
    let mut t = String::new();
    let mut notes = plan.notes.clone();
    let touch_probe = plan.source(0x60B8).is_some() && plan.source(0x60B9).is_some();
    if let (Some(v), Some(p)) = (dev.vendor_id, dev.product_code) {
        let _ = writeln!(
            t,
            "[device]\n# the device as the master finds it on the bus (SII identity, CoE 0x1018)\n\
             vendor_id = 0x{v:08X}\nproduct_code = 0x{p:08X}"
        );
        if let Some(r) = dev.revision {
            let _ = writeln!(t, "revision = 0x{r:08X}");
        }
        let _ = writeln!(
            t,
            "# the vendor's ESI, which `--link ethercat-emu` plays the device from (relative to the\n\
             # current directory, else to this file's)\nesi = \"{}\"",
            toml_escape(dev.reference.as_deref().unwrap_or(&dev.file))
        );
        t.push('\n');
    }
    let with_role: Vec<&plan::RoleSource> =
        plan.used.iter().filter(|s| s.role().is_some()).collect();
    if !with_role.is_empty() {
        let _ = writeln!(
            t,
            "[roles]\n# CiA 402 objects this device carries in objects of its own"
        );
        for s in with_role {
            let Some(r) = s.role() else { continue };
            let name = pdo::role_name(r.index, r.sub).unwrap_or("?");
            let object = format!("0x{:04X}:{:02X}", r.object, r.object_sub);
            let _ = match r.bits {
                None => writeln!(t, "{name} = \"{object}\"   # {}", s.how),
                Some(b) => writeln!(
                    t,
                    "{name} = {{ object = \"{object}\", bits = {b} }}   # {}",
                    s.how
                ),
            };
            if s.how.starts_with("position set-point") {
                notes.push(format!(
                    "0x607A:00 target position: the device has none in a PDO; its fixed RxPDO \
                     carries the position set-point in {object} (interpretation: the Beckhoff \
                     AX2000 / Kollmorgen AKD position interface) — check the drive manual"
                ));
            }
        }
        t.push('\n');
    }
    for (key, d, rx) in [("rxpdo", &plan.rx, true), ("txpdo", &plan.tx, false)] {
        let _ = writeln!(t, "[{key}]");
        let _ = writeln!(
            t,
            "# {}",
            if rx {
                "master -> drive:"
            } else {
                "drive -> master:"
            }
        );
        for e in &d.entries {
            if e.is_gap() {
                let _ = writeln!(t, "#   gap of {} bits", e.bits);
                continue;
            }
            let role = plan
                .used
                .iter()
                .find(|s| s.has(e.index, e.sub))
                .map(|s| format!(" = {}", cia_name(s.index)));
            let name = dev
                .objects
                .iter()
                .find(|o| o.index == e.index && o.sub == e.sub)
                .map_or(String::new(), |o| format!(" {}", one_line(&o.name)));
            let _ = writeln!(
                t,
                "#   0x{:04X}:{:02X}{name} ({} bits){}",
                e.index,
                e.sub,
                e.bits,
                role.unwrap_or_default()
            );
        }
        for (index, why) in plan
            .left_out
            .iter()
            .filter(|(i, _)| pdo::ROLE_NAMES.iter().any(|r| r.1 == *i && r.3 == rx))
        {
            let _ = writeln!(
                t,
                "#   left out: 0x{index:04X}:00 {}: {}",
                cia_name(*index),
                one_line(why)
            );
        }
        if !d.pdos.is_empty() {
            let pdos: Vec<String> = d.pdos.iter().map(|p| format!("\"0x{p:04X}\"")).collect();
            let _ = writeln!(t, "pdos = [{}]", pdos.join(", "));
        }
        if d.fixed {
            let _ = writeln!(
                t,
                "fixed = true   # the device's own mapping: assigned as it is, never written"
            );
        }
        let entries: Vec<String> = d
            .entries
            .iter()
            .map(|e| format!("\"{}\"", pdo::entry_text(e)))
            .collect();
        let _ = writeln!(t, "entries = [{}]", entries.join(", "));
        if !d.defaults.is_empty() {
            let _ = writeln!(
                t,
                "# outputs of the fixed PDO that are no role: values the drive runs with"
            );
            let items: Vec<String> = d
                .defaults
                .iter()
                .map(|(i, s, v, _)| format!("\"0x{i:04X}:{s:02X}\" = {v}"))
                .collect();
            let _ = writeln!(t, "defaults = {{ {} }}", items.join(", "));
            for (i, s, v, why) in &d.defaults {
                notes.push(format!(
                    "0x{i:04X}:{s:02X} {} is in the fixed PDO: written {v} every cycle ({why})",
                    cia_name(*i)
                ));
            }
        }
        t.push('\n');
    }
    for &(_, index, _, _) in pdo::ROLE_NAMES {
        if plan.source(index).is_some() || pdo::is_touch_probe(index) {
            continue;
        }
        if matches!(index, 0x60F4 | 0x6077 | 0x6061) {
            notes.push(format!(
                "0x{index:04X}:00 {} left out: not in the device's PDOs",
                cia_name(index)
            ));
        }
    }
    if !touch_probe {
        notes.push(
            "no touch probe (0x60B8 … 0x60BD, or the modular device profile's TP1 / TP2 bits): no \
             drive latch on this axis; measure with PLC, PLC_TIMESTAMP (a timestamp input \
             terminal such as an EL1252) or PLC_EXT_LATCH_CONTROL (seed 004 §7)"
                .to_string(),
        );
    }
    Sections {
        pdo_text: t,
        touch_probe,
        notes,
    }
}

/// The PDO sections from the CiA 402 objects the file marks mappable (EDS, and every ESI
/// without a [`VendorDevice::plan`]).
fn listed_sections(
    dev: &VendorDevice,
    pdos: Option<&PdoCapacity>,
) -> Result<Sections, VendorError> {
    let kind = dev.kind;
    let mut t = String::new();
    let mut missing = Vec::new();
    for w in &AXIS_PDO {
        if !w.required {
            continue;
        }
        if let Err(why) = pdo_fit(dev.object(w.index, 0), w, kind) {
            missing.push(format!("0x{:04X}:00 {}: {why}", w.index, cia_name(w.index)));
        }
    }
    if !missing.is_empty() {
        return Err(VendorError::MissingObjects {
            file: dev.file.clone(),
            product: dev.product.clone(),
            missing,
        });
    }
    let mut notes = Vec::new();
    let mut left_out = Vec::new();
    let mut rx = Vec::new();
    let mut tx = Vec::new();
    let push = |w: &Wanted, rx_list: &mut Vec<u16>, tx_list: &mut Vec<u16>| {
        if w.rx {
            rx_list.push(w.index);
        } else {
            tx_list.push(w.index);
        }
    };
    for w in &AXIS_PDO {
        match pdo_fit(dev.object(w.index, 0), w, kind) {
            Ok(()) => push(w, &mut rx, &mut tx),
            Err(why) => left_out.push((w.index, why)),
        }
    }
    // Touch probe: the function word out and the status in, and at least one edge value.
    let probe_fit: Vec<(u16, Result<(), String>)> = PROBE_PDO
        .iter()
        .map(|w| (w.index, pdo_fit(dev.object(w.index, 0), w, kind)))
        .collect();
    let core_ok = probe_fit[..2].iter().all(|(_, r)| r.is_ok());
    let values_ok = probe_fit[2..].iter().any(|(_, r)| r.is_ok());
    let mut touch_probe = core_ok && values_ok;
    if touch_probe {
        for (w, (_, r)) in PROBE_PDO.iter().zip(&probe_fit) {
            match r {
                Ok(()) => push(w, &mut rx, &mut tx),
                Err(why) => left_out.push((w.index, why.clone())),
            }
        }
    }
    match pdo_fit(dev.object(TORQUE_ACTUAL.index, 0), &TORQUE_ACTUAL, kind) {
        Ok(()) => push(&TORQUE_ACTUAL, &mut rx, &mut tx),
        Err(why) => left_out.push((TORQUE_ACTUAL.index, why)),
    }
    // The device's PDOs (EDS): what has no room leaves.
    let mut probe_without_room = false;
    if let Some(cap) = pdos {
        let size = |i: u16| dev.object(i, 0).map_or(0, |o| o.bits as usize / 8);
        match capacity::fit(cap, &mut rx, &mut tx, size) {
            Ok(f) => {
                probe_without_room = f.probe_off;
                touch_probe &= !f.probe_off;
                left_out.extend(f.left_out);
            }
            Err(missing) => {
                return Err(VendorError::MissingObjects {
                    file: dev.file.clone(),
                    product: dev.product.clone(),
                    missing,
                })
            }
        }
    }
    for (index, why) in &left_out {
        notes.push(format!(
            "0x{index:04X}:00 {} left out: {why}",
            cia_name(*index)
        ));
    }
    if !touch_probe {
        let absent = probe_fit
            .iter()
            .all(|(_, r)| r.as_ref().is_err_and(|e| e == "not in the file"));
        let why: Vec<String> = if probe_without_room {
            vec!["0x60B8 has no room in the device's RPDOs".into()]
        } else if absent {
            vec!["none of them in the file".into()]
        } else {
            probe_fit
                .iter()
                .filter_map(|(i, r)| r.as_ref().err().map(|e| format!("0x{i:04X} {e}")))
                .collect()
        };
        notes.push(format!(
            "no touch probe (0x60B8 … 0x60BD: {}): no drive latch on this axis; measure with \
             PLC, PLC_TIMESTAMP (a timestamp input terminal such as an EL1252) or \
             PLC_EXT_LATCH_CONTROL (seed 004 §7)",
            if why.is_empty() {
                "no edge value".to_string()
            } else {
                why.join(", ")
            }
        ));
    }

    // PDOs.
    let list = |t: &mut String, out: bool, indices: &[u16]| {
        let _ = writeln!(
            t,
            "{}",
            if out {
                "# master -> drive:"
            } else {
                "# drive -> master:"
            }
        );
        for &i in indices {
            if let Some(o) = dev.object(i, 0) {
                let _ = writeln!(
                    t,
                    "#   0x{i:04X}:00 {} ({}, {} bits)",
                    one_line(&o.name),
                    one_line(&o.type_name),
                    o.bits
                );
            }
        }
        let direction_of = |i: u16| {
            AXIS_PDO
                .iter()
                .chain(PROBE_PDO.iter())
                .chain(std::iter::once(&TORQUE_ACTUAL))
                .find(|w| w.index == i)
                .is_some_and(|w| w.rx)
        };
        for (i, why) in left_out.iter().filter(|(i, _)| direction_of(*i) == out) {
            let _ = writeln!(
                t,
                "#   left out: 0x{i:04X}:00 {}: {}",
                cia_name(*i),
                one_line(why)
            );
        }
        let entries: Vec<String> = indices
            .iter()
            .map(|i| format!("\"0x{i:04X}:00\""))
            .collect();
        let _ = writeln!(t, "entries = [{}]\n", entries.join(", "));
    };
    let _ = writeln!(t, "[rxpdo]");
    list(&mut t, true, &rx);
    let _ = writeln!(t, "[txpdo]");
    list(&mut t, false, &tx);

    Ok(Sections {
        pdo_text: t,
        touch_probe,
        notes,
    })
}

/// `s` without line breaks and control characters, for a TOML comment.
fn one_line(s: &str) -> String {
    s.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect()
}

fn toml_escape(s: &str) -> String {
    let mut out = String::new();
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => {}
            c => out.push(c),
        }
    }
    out
}

pub mod capacity;
pub use capacity::PdoCapacity;

#[cfg(feature = "ethercat")]
mod esi_source;

#[cfg(feature = "ethercat")]
pub mod esi_plan;

pub mod plan;

#[cfg(feature = "canopen")]
mod eds_source;

#[cfg(test)]
mod tests;
