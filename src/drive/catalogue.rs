//! Drive definition files (`drives/*.toml`).
//!
//! A drive definition says which adapter family a drive belongs to, how its process data is laid
//! out, how increments scale to axis units, how the emulated drive behaves, which drive functions
//! (FCT-C4 §7.3.2, `#DRIVE WR [KEY=TORQUE_LIMIT …]`) and which SERCOS IDNs (FCT-C4 §7.3.1,
//! `#IDENT WR [… ID S-0-0092 …]`) map to which objects:
//!
//! ```toml
//! [drive]
//! name = "cia402-generic"
//! profile = "cia402"                      # the only profile so far
//!
//! [scaling]
//! increments_per_unit = 10000             # drive increments per mm (or per degree)
//! offset = 0.0                            # axis position at increment 0
//!
//! [device]                                # optional: the device the file is for, as the
//! vendor_id = 0x0000029C                  # master finds it on the bus (CoE 0x1018:01 …
//! product_code = 0x03B11002               # :03, the SII identity); revision optional
//! revision = 0x00050005
//! esi = "vendor.xml"                      # its ESI: the in-process emulator plays it from there
//!
//! [rxpdo]                                 # master -> drive, default = CSP mapping
//! entries = ["0x6040:00", "0x607A:00", "0x6060:00", "0x60B8:00"]
//! # pdos = ["0x1701"]                     # the PDOs assigned to the outputs (0x1C12), in order;
//! #                                       # default: 0x1600 (EtherCAT), the master's fit (CANopen)
//! # fixed = true                          # the device's own fixed mapping of `pdos`: assigned
//! #                                       # and checked, never written; `entries` is its content,
//! #                                       # gaps "0x0000:00:bit8" and bit fields "…:bit1" allowed
//! # defaults = { "0x6072:00" = 3000 }     # values the adapter writes to mapped objects it does
//! #                                       # not drive (only with 0x6072 in `entries`)
//!
//! [txpdo]                                 # drive -> master
//! entries = ["0x6041:00", "0x6064:00", "0x60F4:00", "0x6061:00", "0x60B9:00",
//!            "0x60BA:00", "0x60BB:00", "0x60BC:00", "0x60BD:00", "0x6077:00"]
//!
//! [model]                                 # drive-model knobs (emulated drive only)
//! kv = 40.0                               # position loop gain, 1/s
//! following_error_window = 30000          # 0x6065, increments; 4294967295 = off
//! following_error_timeout_ms = 10         # 0x6066, ms
//! enable_delay_cycles = 0                 # extra cycles SWITCHED ON -> OPERATION ENABLED
//! max_velocity = 1000.0                   # units/s; absent = unlimited
//! zero_pulse_period = 10000               # increments between encoder zero pulses
//! torque_per_increment = 0.004            # torque demand, per mille of rated per increment of lag
//!
//! [probe]                                 # touch probe behaviour (adapter and model)
//! rearm_requires_zero = false             # drive needs 0x60B8 = 0 before it re-arms
//! arm_timeout_cycles = 100                # cycles the adapter waits for 0x60B9 to confirm
//!
//! [functions]
//! TORQUE_LIMIT = { object = "0x6072:00", type = "u16", unit = "0.1 %", scale = 10.0 }
//! MON_WINDOW = { object = "0x6065:00", type = "u32", unit = "increments" }
//!
//! [roles]                                 # CiA 402 objects played by other objects
//! # controlword = "0x7010:01"             # (Beckhoff MDP 742: 0x7010:01, …); a word made of
//! # touch_probe_function = { object = "0x7001:01", bits = 16 }   # single bits: first + width
//!
//! [idn]                                   # SERCOS IDNs on a CoE drive
//! "S-0-0092" = { object = "0x6072:00", type = "u16" }
//! "S-0-0159" = { object = "0x6065:00", type = "u32", zero = 4294967295 }
//! ```
//!
//! Every error names the file, the 1-based line (from the TOML spans), the key and what is
//! allowed; unknown keys are errors, so a typo never silently falls back to a default.

use super::pdo::{self, DataType, PdoLayout, Role};
use super::DriveError;
use crate::units::Scaling;
use std::ops::Range;
use std::path::Path;
use toml_edit::{ImDocument, Item, TableLike, Value};

/// Drive profile family: which adapter and drive model play the drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Profile {
    /// CiA 402 (CANopen / CoE): [`super::ds402::Ds402Adapter`], [`super::model::ds402::Ds402Model`].
    Cia402,
    /// SERCOS (SoE, AX5000 kind): real-time control / status bits, probe IDNs (FCT-C4 §6.1).
    Sercos,
    /// PROFIdrive (telegrams 3 / 5 / 102 / 105, encoder interface G1_STW / G1_ZSW, FCT-C4 §6.5).
    Profidrive,
    /// Beckhoff Lightbus (AX2000, digital input 2 as probe input, FCT-C4 §6.2).
    Lightbus,
    /// Terminal drive with a KL5101 / EL5101 encoder terminal as position feedback (§6.3).
    Terminal,
}

impl Profile {
    /// Name used in drive files.
    pub const fn name(self) -> &'static str {
        match self {
            Profile::Cia402 => "cia402",
            Profile::Sercos => "sercos",
            Profile::Profidrive => "profidrive",
            Profile::Lightbus => "lightbus",
            Profile::Terminal => "terminal",
        }
    }

    /// Every profile, in drive-file spelling order.
    pub const ALL: [Profile; 5] = [
        Profile::Cia402,
        Profile::Sercos,
        Profile::Profidrive,
        Profile::Lightbus,
        Profile::Terminal,
    ];

    /// The profile of a drive-file name.
    pub fn from_name(name: &str) -> Option<Profile> {
        Profile::ALL.into_iter().find(|p| p.name() == name)
    }
}

/// Behaviour knobs of the emulated drive (`[model]`); the real drive ignores them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelConfig {
    /// Position loop gain kv in 1/s (default 40). With feed-forward it only corrects residual
    /// errors; without (`feed_forward = false`) the steady-state lag is v / kv.
    pub kv: f64,
    /// The drive runs its cascade with velocity and acceleration feed-forward from the
    /// set-point sequence, as CSP servo drives do (default `true`). `false` is a plain
    /// first-order position loop without feed-forward: lag v / kv at constant speed, torque =
    /// lag × `torque_per_increment` (a drive of that kind exists in the field).
    pub feed_forward: bool,
    /// Velocity feed-forward gain, fraction of the set-point velocity (default 1.0).
    pub velocity_feed_forward: f64,
    /// Acceleration (torque) feed-forward gain, fraction of the set-point acceleration
    /// (default 1.0).
    pub acceleration_feed_forward: f64,
    /// Time constant of the speed loop in ms (default 1.0): the actual speed follows the
    /// speed command as a first-order lag.
    pub velocity_loop_ms: f64,
    /// Acceleration of the axis at rated torque, units/s² (default 20000): the torque demand
    /// (0x6077, ‰) is the demanded acceleration / this × 1000, and a torque limit caps the
    /// acceleration at limit / 1000 × this.
    pub rated_acceleration: f64,
    /// Initial following error window 0x6065 in increments (default 30000; `u32::MAX` = off).
    pub following_error_window: u32,
    /// Initial following error time out 0x6066 in ms (default 10).
    pub following_error_timeout_ms: u16,
    /// Extra cycles the drive needs from *switched on* to *operation enabled* (default 0).
    pub enable_delay_cycles: u32,
    /// Largest speed the position loop moves, units/s (`None` = unlimited).
    pub max_velocity: Option<f64>,
    /// Distance between two zero pulses (index, C-phase) of the emulated position encoder, in
    /// increments (default 10000 = one pulse per mm at 10000 inc/mm, i.e. a 1 mm "revolution").
    /// Zero pulses sit at every integer multiple of the period (0x60B8 source 01b).
    pub zero_pulse_period: f64,
    /// Torque demand per increment of following error, in per mille of rated torque (0x6077 =
    /// 0x60F4 × this, clipped to the torque limit; default 0.004, see
    /// [`DEFAULT_TORQUE_PER_INCREMENT`]). 0 = the model produces no torque.
    pub torque_per_increment: f64,
}

/// Default `[model] torque_per_increment`: 0.004 ‰ per increment. The model's position loop has
/// no velocity feed-forward, so its lag is v / kv and a torque proportional to the lag is a
/// viscous load: at the generic drive's largest speed (1000 mm/s, lag 25 mm = 250000 inc at
/// kv = 40 1/s) the demand is 1000 ‰ = rated torque; at 100 mm/min it is 1.7 ‰. Pressed against
/// a fixed stop the lag grows with the commanded feed and a 10 % limit (100 ‰) is reached at
/// 25000 inc = 2.5 mm of lag.
pub const DEFAULT_TORQUE_PER_INCREMENT: f64 = 0.004;

/// Default `[model] velocity_loop_ms`: a speed loop with a bandwidth of about 160 Hz.
pub const DEFAULT_VELOCITY_LOOP_MS: f64 = 1.0;

/// Default `[model] rated_acceleration` in units/s² (20 m/s² at rated torque: a 10 % torque
/// limit still allows 2 m/s², twice the seeds' default P-AXIS-00004).
pub const DEFAULT_RATED_ACCELERATION: f64 = 20_000.0;

/// Default `[model] zero_pulse_period` in increments.
pub const DEFAULT_ZERO_PULSE_PERIOD: f64 = 10_000.0;

/// Default `[probe] arm_timeout_cycles`.
pub const DEFAULT_ARM_TIMEOUT_CYCLES: u32 = 100;

/// Touch probe behaviour of the drive (`[probe]`); read by the adapter and by the model, which
/// plays the same drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProbeConfig {
    /// The drive re-arms a touch probe only when it sees 0x60B8's enable bit go 0 → 1, so the
    /// adapter always writes 0 first and waits for 0x60B9 to show the probe disabled (default
    /// `false`; modelled on drives whose manuals demand 0x60B8 = 0 before a new configuration).
    pub rearm_requires_zero: bool,
    /// Cycles the adapter waits for 0x60B9 to confirm a step of the arming sequence before it
    /// reports the latch as failed (default 100).
    pub arm_timeout_cycles: u32,
}

impl Default for ProbeConfig {
    fn default() -> Self {
        ProbeConfig {
            rearm_requires_zero: false,
            arm_timeout_cycles: DEFAULT_ARM_TIMEOUT_CYCLES,
        }
    }
}

impl Default for ModelConfig {
    /// The Leadshine EL7 factory values for 0x6065 / 0x6066 (from an SDO dump of a real drive).
    fn default() -> Self {
        ModelConfig {
            kv: 40.0,
            feed_forward: true,
            velocity_feed_forward: 1.0,
            acceleration_feed_forward: 1.0,
            velocity_loop_ms: DEFAULT_VELOCITY_LOOP_MS,
            rated_acceleration: DEFAULT_RATED_ACCELERATION,
            following_error_window: 30_000,
            following_error_timeout_ms: 10,
            enable_delay_cycles: 0,
            max_velocity: None,
            zero_pulse_period: DEFAULT_ZERO_PULSE_PERIOD,
            torque_per_increment: DEFAULT_TORQUE_PER_INCREMENT,
        }
    }
}

/// A value the adapter writes every cycle to a mapped output object it does not drive itself
/// (`[rxpdo] defaults`, e.g. 0x6072 max torque).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputDefault {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Value (fits the mapped type).
    pub value: i64,
}

/// One entry of the drive function table (FCT-C4 §7.3.2: `antr.function[i]`).
#[derive(Debug, Clone, PartialEq)]
pub struct DriveFunction {
    /// Key used by `#DRIVE … KEY=…` (upper case, e.g. `TORQUE_LIMIT`).
    pub key: String,
    /// Object index (`wr_ident`).
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Data type on the wire.
    pub ty: DataType,
    /// Unit of the wire value, for display (`"0.1 %"`).
    pub unit: Option<String>,
    /// Linear scaling: wire value = round(value × scale) (seed: `scaling_type LINEAR`,
    /// `scaling_factor`); 1.0 = unscaled.
    pub scale: f64,
    /// Smallest allowed wire value.
    pub min: i64,
    /// Largest allowed wire value.
    pub max: i64,
    /// `commu = "CYCLIC"`: the value goes into the cyclic telegram through the adapter (e.g.
    /// PROFIdrive MOMRED); default `"ACYCLIC"`: an object write over the mailbox (FCT-C4
    /// §7.3.2 `antr.function[i].commu`).
    pub cyclic: bool,
}

impl DriveFunction {
    /// Wire value for a user value, `None` when it is not finite or outside `min..=max`.
    pub fn encode(&self, value: f64) -> Option<i64> {
        let raw = (value * self.scale).round();
        if !raw.is_finite() || raw < self.min as f64 || raw > self.max as f64 {
            return None;
        }
        Some(raw as i64)
    }

    /// User value of a wire value.
    pub fn decode(&self, raw: i64) -> f64 {
        raw as f64 / self.scale
    }
}

/// A SERCOS IDN mapped onto a CiA 402 object (`[idn]`), so that `#IDENT WR/RD [… ID S-0-0092 …]`
/// (FCT-C4 §7.3.1) works on a CoE / CANopen drive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdnMapping {
    /// Normalised IDN (`S-0-0092`, see [`normalize_idn`]).
    pub idn: String,
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Data type of the object.
    pub ty: DataType,
    /// Object value that stands for the SERCOS value 0, when the two profiles spell a special
    /// meaning differently: S-0-0159 "monitoring window 0 = monitoring off" is CiA 402 0x6065
    /// = 0xFFFFFFFF.
    pub zero: Option<i64>,
}

impl IdnMapping {
    /// Object value for a SERCOS value: 0 becomes [`zero`](Self::zero) when set, other values
    /// pass unchanged; `None` when the result does not fit the object's type.
    pub fn encode(&self, value: i64) -> Option<i64> {
        let raw = match self.zero {
            Some(z) if value == 0 => z,
            _ => value,
        };
        self.ty.contains(raw).then_some(raw)
    }

    /// SERCOS value of an object value: [`zero`](Self::zero) reads back as 0.
    pub fn decode(&self, raw: i64) -> i64 {
        if self.zero == Some(raw) {
            0
        } else {
            raw
        }
    }
}

/// Normalise a SERCOS IDN: `S-0-92`, `s-0-0092`, ` S-0-0092 ` → `S-0-0092`. Accepts standard
/// (`S`) and product-specific (`P`) IDNs with parameter set 0..=7 and number 0..=4095
/// (IEC 61800-7-204 IDN structure); `None` otherwise.
pub fn normalize_idn(text: &str) -> Option<String> {
    let mut parts = text.trim().split('-');
    let (kind, set, number) = (parts.next()?, parts.next()?, parts.next()?);
    if parts.next().is_some() {
        return None;
    }
    let kind = match kind.trim() {
        "S" | "s" => 'S',
        "P" | "p" => 'P',
        _ => return None,
    };
    let digits = |s: &str, max: u32| -> Option<u32> {
        let s = s.trim();
        if s.is_empty() || s.len() > 6 || !s.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        s.parse::<u32>().ok().filter(|v| *v <= max)
    };
    let set = digits(set, 7)?;
    let number = digits(number, 4095)?;
    Some(format!("{kind}-{set}-{number:04}"))
}

/// A parsed drive definition file.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveDefinition {
    /// `[drive] name`.
    pub name: String,
    /// `[drive] profile`.
    pub profile: Profile,
    /// The whole file text: a family module parses its own section (`[sercos]`, `[profidrive]`,
    /// `[lightbus]`, `[terminal]`) from it, with line numbers.
    pub source: String,
    /// Where the definition came from (file path or `builtin:NAME`).
    pub file: String,
    /// `[scaling]`.
    pub scaling: Scaling,
    /// `[rxpdo] entries` (master → drive).
    pub rxpdo: PdoLayout,
    /// `[rxpdo] defaults`.
    pub rxpdo_defaults: Vec<OutputDefault>,
    /// `[txpdo] entries` (drive → master).
    pub txpdo: PdoLayout,
    /// `[model]`.
    pub model: ModelConfig,
    /// `[functions]`, in file order.
    pub functions: Vec<DriveFunction>,
    /// `[probe]`.
    pub probe: ProbeConfig,
    /// `[idn]`, in file order.
    pub idns: Vec<IdnMapping>,
    /// `[device]`: the device this definition is for, if the file names it.
    pub identity: Option<DeviceIdentity>,
    /// `[device] esi`: the vendor's ESI file of that device (`drive from-esi` writes it), which
    /// the in-process emulated bus (`ethercat-emu`) plays the device from; relative paths are
    /// taken from the current directory, then from the drive file's directory.
    pub esi: Option<String>,
    /// `[roles]`: CiA 402 objects played by other objects of the device.
    pub roles: Vec<Role>,
    /// `[rxpdo] pdos` / `fixed`.
    pub rx_assign: PdoAssign,
    /// `[txpdo] pdos` / `fixed`.
    pub tx_assign: PdoAssign,
}

/// `[device]`: the identity of the device a definition is for — what a master compares with
/// the SubDevice's SII / CoE 0x1018 (ETG.1000.6; CiA 301 0x1018:01 … :03).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DeviceIdentity {
    /// Vendor id (0x1018:01).
    pub vendor_id: u32,
    /// Product code (0x1018:02).
    pub product_code: u32,
    /// Revision number (0x1018:03), if the definition is for one revision.
    pub revision: Option<u32>,
}

impl std::fmt::Display for DeviceIdentity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "vendor {:#010x} product {:#010x}",
            self.vendor_id, self.product_code
        )?;
        if let Some(r) = self.revision {
            write!(f, " revision {r:#010x}")?;
        }
        Ok(())
    }
}

/// `[rxpdo]` / `[txpdo]` `pdos` and `fixed`: which PDOs carry the entries.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PdoAssign {
    /// The PDOs (mapping objects 0x1600… / 0x1A00…) in assignment order; empty: the link's
    /// default (EtherCAT: 0x1600 / 0x1A00; CANopen: the PDOs the master fits the entries into).
    pub pdos: Vec<u16>,
    /// The PDOs are the device's fixed mappings: the master assigns them and reads their
    /// mapping back (it must equal the entries), never writes it (ETG.2000 `RxPdo Fixed`).
    pub fixed: bool,
}

impl DriveDefinition {
    /// The drive can latch a probe edge itself (seed 004 §6, signal DRIVE): a CiA 402 drive
    /// needs its touch probe, the function 0x60B8 in the RxPDO and the status 0x60B9 in the
    /// TxPDO (§6.4); the other families carry their latch in their own telegrams (SERCOS
    /// real-time bits, PROFIdrive encoder interface, Lightbus input 2, the encoder terminal's
    /// latch). Without it the axis measures through the CNC (§7): PLC, PLC_TIMESTAMP,
    /// PLC_EXT_LATCH_CONTROL.
    pub fn has_drive_latch(&self) -> bool {
        self.profile != Profile::Cia402
            || (self.rxpdo.contains(0x60B8, 0) && self.txpdo.contains(0x60B9, 0))
    }

    /// The device's object that plays CiA 402 object `index:sub` (`[roles]`), else the object
    /// itself: where the master reads or writes it by SDO (e.g. the mode of operation 0x6060 of
    /// a Beckhoff MDP 742 terminal is 0x7010:03).
    pub fn object_of(&self, index: u16, sub: u8) -> (u16, u8) {
        self.roles
            .iter()
            .find(|r| r.index == index && r.sub == sub && r.bits.is_none())
            .map_or((index, sub), |r| (r.object, r.object_sub))
    }

    /// The drive function with this key.
    pub fn function(&self, key: &str) -> Option<&DriveFunction> {
        self.functions.iter().find(|f| f.key == key)
    }

    /// Data type of object `index:sub` as the definition knows it: its `[functions]`, `[idn]`,
    /// RxPDO or TxPDO entries, first match.
    pub fn object_type(&self, index: u16, sub: u8) -> Option<DataType> {
        self.functions
            .iter()
            .find(|f| f.index == index && f.sub == sub)
            .map(|f| f.ty)
            .or_else(|| {
                self.idns
                    .iter()
                    .find(|m| m.index == index && m.sub == sub)
                    .map(|m| m.ty)
            })
            .or_else(|| self.rxpdo.find(index, sub).map(|e| e.ty))
            .or_else(|| self.txpdo.find(index, sub).map(|e| e.ty))
    }

    /// The object a SERCOS IDN maps to (`[idn]`); the name is normalised first, so `s-0-92`
    /// finds `S-0-0092`.
    pub fn idn(&self, idn: &str) -> Option<&IdnMapping> {
        let n = normalize_idn(idn)?;
        self.idns.iter().find(|m| m.idn == n)
    }
}

/// The drive files compiled into the crate: one line per file (name, text).
const BUILTINS: &[(&str, &str)] = &[
    (
        "cia402-generic",
        include_str!("../../drives/cia402-generic.toml"),
    ),
    (
        "cia402-no-feedforward",
        include_str!("../../drives/cia402-no-feedforward.toml"),
    ),
    (
        "cia402-drive-defined",
        include_str!("../../drives/cia402-drive-defined.toml"),
    ),
    (
        "sercos-ax5000",
        include_str!("../../drives/sercos-ax5000.toml"),
    ),
    (
        "ax2000-lightbus",
        include_str!("../../drives/ax2000-lightbus.toml"),
    ),
    (
        "kl5101-terminal",
        include_str!("../../drives/kl5101-terminal.toml"),
    ),
    (
        "el5101-terminal",
        include_str!("../../drives/el5101-terminal.toml"),
    ),
    (
        "profidrive-t105",
        include_str!("../../drives/profidrive-t105.toml"),
    ),
];

const BUILTIN_NAMES: &[&str] = &{
    let mut names = [""; BUILTINS.len()];
    let mut i = 0;
    while i < BUILTINS.len() {
        names[i] = BUILTINS[i].0;
        i += 1;
    }
    names
};

/// Names of the drive definitions compiled into the crate (`drives/*.toml`).
pub fn builtin_names() -> &'static [&'static str] {
    BUILTIN_NAMES
}

/// A built-in drive definition by name (`cia402-generic`).
pub fn builtin(name: &str) -> Option<DriveDefinition> {
    let (_, text) = BUILTINS.iter().find(|(n, _)| *n == name)?;
    // The built-in files are checked by a unit test; a broken one reads as "not there".
    parse(text, &format!("builtin:{name}")).ok()
}

/// A built-in definition by name, else the file at `name_or_path`.
pub fn load(name_or_path: &str) -> Result<DriveDefinition, DriveError> {
    if let Some(def) = builtin(name_or_path) {
        return Ok(def);
    }
    let text = crate::limits::read_text(
        Path::new(name_or_path),
        "drive definition file",
        crate::limits::MAX_DRIVE_FILE_BYTES,
    )
    .map_err(|e| DriveError::Definition {
        file: name_or_path.to_string(),
        line: 0,
        message: format!(
            "not a built-in drive ({}) and cannot read it as a file: {e}",
            BUILTIN_NAMES.join(", ")
        ),
    })?;
    parse(&text, name_or_path)
}

/// Parse a drive definition; `file` names the source in errors.
pub fn parse(text: &str, file: &str) -> Result<DriveDefinition, DriveError> {
    let cx = Cx { text, file };
    let doc = ImDocument::parse(text).map_err(|e| {
        let msg = e.message().trim().replace('\n', "; ");
        cx.err(e.span(), format!("TOML syntax: {msg}"))
    })?;
    let root = doc.as_table();
    cx.check_keys(
        root,
        "",
        &[
            "drive",
            "scaling",
            "rxpdo",
            "txpdo",
            "model",
            "probe",
            "functions",
            "idn",
            "device",
            "roles",
            // The family's own section, parsed by its module from `DriveDefinition::source`.
            "sercos",
            "profidrive",
            "lightbus",
            "terminal",
        ],
    )?;

    let drive = cx.table(root, "drive", None)?;
    let drive =
        drive.ok_or_else(|| cx.err(None, "missing table [drive] (name, profile)".into()))?;
    cx.check_keys(drive.1, "[drive]", &["name", "profile"])?;
    let name = cx.req_str(&drive, "[drive]", "name")?;
    let profile_name = cx.req_str(&drive, "[drive]", "profile")?;
    let profile = Profile::from_name(&profile_name).ok_or_else(|| {
        let allowed: Vec<String> = Profile::ALL
            .iter()
            .map(|p| format!("\"{}\"", p.name()))
            .collect();
        cx.err(
            cx.value_span(drive.1, "profile"),
            format!(
                "[drive] profile: unknown profile \"{profile_name}\"; allowed: {}",
                allowed.join(", ")
            ),
        )
    })?;
    for p in Profile::ALL {
        if p != profile && p != Profile::Cia402 && root.contains_key(p.name()) {
            return Err(cx.err(
                root.get(p.name()).and_then(|i| i.span()),
                format!(
                    "[{}] does not belong to a drive of profile \"{}\"",
                    p.name(),
                    profile.name()
                ),
            ));
        }
    }

    let scaling = cx
        .table(root, "scaling", None)?
        .ok_or_else(|| cx.err(None, "missing table [scaling] (increments_per_unit)".into()))?;
    cx.check_keys(scaling.1, "[scaling]", &["increments_per_unit", "offset"])?;
    let inc = cx
        .float(scaling.1, "[scaling]", "increments_per_unit")?
        .ok_or_else(|| {
            cx.err(
                scaling.0.clone(),
                "[scaling] increments_per_unit is missing".into(),
            )
        })?;
    if inc == 0.0 {
        return Err(cx.err(
            cx.value_span(scaling.1, "increments_per_unit"),
            "[scaling] increments_per_unit: must be a non-zero number".into(),
        ));
    }
    let offset = cx.float(scaling.1, "[scaling]", "offset")?.unwrap_or(0.0);
    let scaling = Scaling {
        increments_per_unit: inc,
        offset,
    };

    let identity = cx.identity(root)?;
    let esi = match cx.table(root, "device", None)? {
        Some(t) => cx.opt_str(t.1, "[device]", "esi")?,
        None => None,
    };
    let roles = cx.roles(root)?;
    let (rxpdo, rxpdo_defaults, rx_assign) =
        cx.pdo(root, "rxpdo", pdo::DEFAULT_RXPDO, true, &roles)?;
    let (txpdo, _, tx_assign) = cx.pdo(root, "txpdo", pdo::DEFAULT_TXPDO, false, &roles)?;
    let needed_pdo: &[(&PdoLayout, &str, [u16; 2])] = if profile == Profile::Cia402 {
        &[
            (&rxpdo, "rxpdo", [0x6040, 0x607A]),
            (&txpdo, "txpdo", [0x6041, 0x6064]),
        ]
    } else {
        &[]
    };
    for &(layout, table, needed) in needed_pdo {
        for index in needed {
            if !layout.contains(index, 0) {
                let span = root
                    .get(table)
                    .and_then(|t| t.as_table_like()?.get("entries")?.span());
                return Err(cx.err(
                    span,
                    format!("[{table}] entries: profile cia402 needs 0x{index:04X}:00 mapped"),
                ));
            }
        }
    }

    let model = cx.model(root)?;
    let probe = cx.probe(root)?;
    let functions = cx.functions(root)?;
    let idns = cx.idns(root)?;
    Ok(DriveDefinition {
        name,
        profile,
        source: text.to_string(),
        file: file.to_string(),
        scaling,
        rxpdo,
        rxpdo_defaults,
        txpdo,
        model,
        functions,
        probe,
        idns,
        identity,
        esi,
        roles,
        rx_assign,
        tx_assign,
    })
}

/// Parse context: the text (for line numbers) and the file name.
struct Cx<'a> {
    text: &'a str,
    file: &'a str,
}

type Tbl<'d> = (Option<Range<usize>>, &'d dyn TableLike);

impl Cx<'_> {
    fn err(&self, span: Option<Range<usize>>, message: String) -> DriveError {
        let line = span.map_or(0, |s| {
            let end = s.start.min(self.text.len());
            self.text.as_bytes()[..end]
                .iter()
                .filter(|&&b| b == b'\n')
                .count()
                + 1
        });
        DriveError::Definition {
            file: self.file.to_string(),
            line,
            message,
        }
    }

    fn key_span(&self, t: &dyn TableLike, key: &str) -> Option<Range<usize>> {
        t.get_key_value(key)
            .and_then(|(k, v)| k.span().or_else(|| v.span()))
    }

    fn value_span(&self, t: &dyn TableLike, key: &str) -> Option<Range<usize>> {
        t.get_key_value(key)
            .and_then(|(k, v)| v.span().or_else(|| k.span()))
    }

    fn check_keys(
        &self,
        t: &dyn TableLike,
        what: &str,
        allowed: &[&str],
    ) -> Result<(), DriveError> {
        for (k, _) in t.iter() {
            if !allowed.contains(&k) {
                let place = if what.is_empty() {
                    "the top level"
                } else {
                    what
                };
                return Err(self.err(
                    self.key_span(t, k),
                    format!(
                        "unknown key `{k}` in {place}; allowed: {}",
                        allowed.join(", ")
                    ),
                ));
            }
        }
        Ok(())
    }

    fn table<'d>(
        &self,
        parent: &'d dyn TableLike,
        key: &str,
        what: Option<&str>,
    ) -> Result<Option<Tbl<'d>>, DriveError> {
        let Some(item) = parent.get(key) else {
            return Ok(None);
        };
        match item.as_table_like() {
            Some(t) => Ok(Some((self.key_span(parent, key), t))),
            None => Err(self.err(
                self.value_span(parent, key),
                format!(
                    "{}{key}: expected a table",
                    what.map(|w| format!("{w} ")).unwrap_or_default()
                ),
            )),
        }
    }

    fn value<'d>(&self, t: &'d dyn TableLike, key: &str) -> Option<&'d Value> {
        t.get(key).and_then(Item::as_value)
    }

    fn req_str(&self, t: &Tbl<'_>, what: &str, key: &str) -> Result<String, DriveError> {
        match self.value(t.1, key) {
            Some(Value::String(s)) => Ok(s.value().clone()),
            Some(_) => Err(self.err(
                self.value_span(t.1, key),
                format!("{what} {key}: expected a string"),
            )),
            None => Err(self.err(t.0.clone(), format!("{what} {key} is missing"))),
        }
    }

    fn opt_str(
        &self,
        t: &dyn TableLike,
        what: &str,
        key: &str,
    ) -> Result<Option<String>, DriveError> {
        match t.get(key) {
            None => Ok(None),
            Some(Item::Value(Value::String(s))) => Ok(Some(s.value().clone())),
            Some(_) => Err(self.err(
                self.value_span(t, key),
                format!("{what} {key}: expected a string"),
            )),
        }
    }

    /// A finite number (integer or float).
    fn float(&self, t: &dyn TableLike, what: &str, key: &str) -> Result<Option<f64>, DriveError> {
        let v = match t.get(key) {
            None => return Ok(None),
            Some(Item::Value(Value::Float(f))) => *f.value(),
            Some(Item::Value(Value::Integer(i))) => *i.value() as f64,
            Some(_) => f64::NAN,
        };
        if v.is_finite() {
            Ok(Some(v))
        } else {
            Err(self.err(
                self.value_span(t, key),
                format!("{what} {key}: expected a finite number"),
            ))
        }
    }

    /// An integer in `lo..=hi`.
    fn int(
        &self,
        t: &dyn TableLike,
        what: &str,
        key: &str,
        lo: i64,
        hi: i64,
    ) -> Result<Option<i64>, DriveError> {
        match t.get(key) {
            None => Ok(None),
            Some(Item::Value(Value::Integer(i))) if (lo..=hi).contains(i.value()) => {
                Ok(Some(*i.value()))
            }
            Some(_) => Err(self.err(
                self.value_span(t, key),
                format!("{what} {key}: expected an integer in {lo}..={hi}"),
            )),
        }
    }

    fn pdo(
        &self,
        root: &dyn TableLike,
        key: &str,
        default: &[&str],
        with_defaults: bool,
        roles: &[Role],
    ) -> Result<(PdoLayout, Vec<OutputDefault>, PdoAssign), DriveError> {
        let what = format!("[{key}]");
        let with_roles = |layout: PdoLayout, span: Option<Range<usize>>| {
            layout
                .with_roles(roles)
                .map_err(|e| self.err(span, format!("[roles]: {e}")))
        };
        let Some(t) = self.table(root, key, None)? else {
            let layout = PdoLayout::parse(default).map_err(|e| self.err(None, e.to_string()))?;
            return Ok((with_roles(layout, None)?, Vec::new(), PdoAssign::default()));
        };
        let allowed: &[&str] = if with_defaults {
            &["entries", "defaults", "pdos", "fixed"]
        } else {
            &["entries", "pdos", "fixed"]
        };
        self.check_keys(t.1, &what, allowed)?;
        let layout = match t.1.get("entries") {
            None => PdoLayout::parse(default).map_err(|e| self.err(None, e.to_string()))?,
            Some(item) => {
                let arr = item.as_array().ok_or_else(|| {
                    self.err(
                        self.value_span(t.1, "entries"),
                        format!("{what} entries: expected an array of strings like \"0x6040:00\""),
                    )
                })?;
                let mut objects: Vec<pdo::EntrySpec> = Vec::new();
                for v in arr.iter() {
                    let s = v.as_str().ok_or_else(|| {
                        self.err(v.span(), format!("{what} entries: expected a string like \"0x6040:00\", \"0x2000:01:u32\", \"0x7001:01:bit1\" or a gap \"0x0000:00:bit8\""))
                    })?;
                    let o = pdo::parse_entry_spec(s)
                        .map_err(|e| self.err(v.span(), format!("{what} entries: {e}")))?;
                    if !o.is_gap()
                        && objects
                            .iter()
                            .any(|e| !e.is_gap() && (e.index, e.sub) == (o.index, o.sub))
                    {
                        return Err(self.err(
                            v.span(),
                            format!("{what} entries: object {s} is mapped twice"),
                        ));
                    }
                    objects.push(o);
                }
                PdoLayout::from_specs(&objects)
                    .map_err(|e| self.err(item.span(), format!("{what} entries: {e}")))?
            }
        };
        let layout = with_roles(layout, self.value_span(t.1, "entries"))?;
        let mut assign = PdoAssign::default();
        if let Some(item) = t.1.get("pdos") {
            let span = self.value_span(t.1, "pdos");
            let range = if key == "rxpdo" {
                0x1600..=0x17FF
            } else {
                0x1A00..=0x1BFF
            };
            let bad = || {
                self.err(
                    span.clone(),
                    format!(
                        "{what} pdos: expected an array of PDO indices {:#06X} … {:#06X}, e.g. \
                         [\"{:#06X}\"]",
                        range.start(),
                        range.end(),
                        range.start()
                    ),
                )
            };
            let arr = item.as_array().ok_or_else(bad)?;
            for v in arr.iter() {
                let n = match v {
                    Value::Integer(i) => u16::try_from(*i.value()).ok(),
                    Value::String(s) => crate::drive::pdo::parse_hex_u16(s.value()),
                    _ => None,
                }
                .filter(|n| range.contains(n))
                .ok_or_else(bad)?;
                if assign.pdos.contains(&n) {
                    return Err(self.err(v.span(), format!("{what} pdos: {n:#06X} is given twice")));
                }
                assign.pdos.push(n);
            }
            if assign.pdos.is_empty() {
                return Err(bad());
            }
        }
        if let Some(f) = self.bool(t.1, &what, "fixed")? {
            if f && assign.pdos.is_empty() {
                return Err(self.err(
                    self.value_span(t.1, "fixed"),
                    format!("{what} fixed = true: name the fixed PDOs in `pdos`"),
                ));
            }
            assign.fixed = f;
        }
        let mut defaults = Vec::new();
        if let Some(d) = self.table(t.1, "defaults", Some(&what))? {
            for (k, _) in d.1.iter() {
                let span = self.key_span(d.1, k);
                // The type comes from the mapping, so vendor objects need none here.
                let (index, sub) = match pdo::parse_entry(k) {
                    Ok((index, sub, _)) | Err(pdo::PdoError::UnknownObject { index, sub }) => {
                        (index, sub)
                    }
                    Err(e) => return Err(self.err(span, format!("{what} defaults: {e}"))),
                };
                let entry = layout.find(index, sub).ok_or_else(|| {
                    self.err(
                        span.clone(),
                        format!("{what} defaults: {k} is not in {what} entries"),
                    )
                })?;
                let (lo, hi) = entry.ty.range();
                let value = self
                    .int(d.1, &format!("{what} defaults"), k, lo, hi)?
                    .unwrap_or(0);
                defaults.push(OutputDefault { index, sub, value });
            }
        }
        Ok((layout, defaults, assign))
    }

    /// `[device]`: `vendor_id`, `product_code` (required), `revision` (optional); integers or
    /// strings with 0x hex.
    fn identity(&self, root: &dyn TableLike) -> Result<Option<DeviceIdentity>, DriveError> {
        let Some(t) = self.table(root, "device", None)? else {
            return Ok(None);
        };
        let w = "[device]";
        self.check_keys(t.1, w, &["vendor_id", "product_code", "revision", "esi"])?;
        let num = |key: &str| -> Result<Option<u32>, DriveError> {
            let Some(item) = t.1.get(key) else {
                return Ok(None);
            };
            let v = match item.as_value() {
                Some(Value::Integer(i)) => u32::try_from(*i.value()).ok(),
                Some(Value::String(s)) => crate::drive::pdo::parse_number_u32(s.value()),
                _ => None,
            };
            v.map(Some).ok_or_else(|| {
                self.err(
                    self.value_span(t.1, key),
                    format!(
                        "{w} {key}: expected a number 0 … 0xFFFFFFFF (decimal, or 0x hex as a TOML \
                         integer or string)"
                    ),
                )
            })
        };
        let missing = |key: &str| {
            self.err(
                t.0.clone(),
                format!("{w} {key} is missing (the device's 0x1018 identity)"),
            )
        };
        let vendor_id = num("vendor_id")?.ok_or_else(|| missing("vendor_id"))?;
        let product_code = num("product_code")?.ok_or_else(|| missing("product_code"))?;
        Ok(Some(DeviceIdentity {
            vendor_id,
            product_code,
            revision: num("revision")?,
        }))
    }

    /// `[roles]`: role name ([`pdo::ROLE_NAMES`]) → `"0xIIII:SS"` or
    /// `{ object = "0xIIII:SS", bits = N }`.
    fn roles(&self, root: &dyn TableLike) -> Result<Vec<Role>, DriveError> {
        let mut out: Vec<Role> = Vec::new();
        let Some(t) = self.table(root, "roles", None)? else {
            return Ok(out);
        };
        let names: Vec<&str> = pdo::ROLE_NAMES.iter().map(|r| r.0).collect();
        for (key, item) in t.1.iter() {
            let kspan = self.key_span(t.1, key);
            let Some(&(_, index, sub, _)) = pdo::ROLE_NAMES.iter().find(|r| r.0 == key) else {
                return Err(self.err(
                    kspan,
                    format!("[roles] {key}: unknown role; allowed: {}", names.join(", ")),
                ));
            };
            let what = format!("[roles] {key}");
            let (text, bits, span) = match item {
                Item::Value(Value::String(s)) => (s.value().clone(), None, item.span()),
                _ => match item.as_table_like() {
                    Some(f) => {
                        self.check_keys(f, &what, &["object", "bits"])?;
                        let o = self.opt_str(f, &what, "object")?.ok_or_else(|| {
                            self.err(kspan.clone(), format!("{what}: `object` is missing"))
                        })?;
                        let bits = self.int(f, &what, "bits", 1, 32)?.map(|b| b as u16);
                        (o, bits, self.value_span(f, "object"))
                    }
                    None => {
                        return Err(self.err(
                            item.span(),
                            format!(
                                "{what}: expected an object \"0xIIII:SS\" or {{ object = \
                                 \"0xIIII:SS\", bits = N }}"
                            ),
                        ))
                    }
                },
            };
            let (object, object_sub) = match pdo::parse_entry_spec(&text) {
                Ok(e) if !e.is_gap() => (e.index, e.sub),
                Err(pdo::PdoError::UnknownObject { index, sub }) => (index, sub),
                Ok(_) => return Err(self.err(span, format!("{what}: a gap plays no role"))),
                Err(e) => return Err(self.err(span, format!("{what}: {e}"))),
            };
            out.push(Role {
                index,
                sub,
                object,
                object_sub,
                bits,
            });
        }
        Ok(out)
    }

    fn model(&self, root: &dyn TableLike) -> Result<ModelConfig, DriveError> {
        let mut m = ModelConfig::default();
        let Some(t) = self.table(root, "model", None)? else {
            return Ok(m);
        };
        let w = "[model]";
        self.check_keys(
            t.1,
            w,
            &[
                "kv",
                "feed_forward",
                "velocity_feed_forward",
                "acceleration_feed_forward",
                "velocity_loop_ms",
                "rated_acceleration",
                "following_error_window",
                "following_error_timeout_ms",
                "enable_delay_cycles",
                "max_velocity",
                "zero_pulse_period",
                "torque_per_increment",
            ],
        )?;
        if let Some(kv) = self.float(t.1, w, "kv")? {
            if kv <= 0.0 {
                return Err(self.err(
                    self.value_span(t.1, "kv"),
                    format!("{w} kv: must be > 0 (1/s), got {kv}"),
                ));
            }
            m.kv = kv;
        }
        if let Some(v) = self.bool(t.1, w, "feed_forward")? {
            m.feed_forward = v;
        }
        for (key, slot) in [
            ("velocity_feed_forward", &mut m.velocity_feed_forward),
            (
                "acceleration_feed_forward",
                &mut m.acceleration_feed_forward,
            ),
        ] {
            if let Some(v) = self.float(t.1, w, key)? {
                if !(0.0..=1.5).contains(&v) {
                    return Err(self.err(
                        self.value_span(t.1, key),
                        format!(
                            "{w} {key}: must be 0 ..= 1.5 (fraction of the set-point's), got {v}"
                        ),
                    ));
                }
                *slot = v;
            }
        }
        if let Some(v) = self.float(t.1, w, "velocity_loop_ms")? {
            if !(v > 0.0 && v <= 100.0) {
                return Err(self.err(
                    self.value_span(t.1, "velocity_loop_ms"),
                    format!("{w} velocity_loop_ms: must be > 0 and <= 100 (ms), got {v}"),
                ));
            }
            m.velocity_loop_ms = v;
        }
        if let Some(v) = self.float(t.1, w, "rated_acceleration")? {
            if !(v > 0.0 && v.is_finite()) {
                return Err(self.err(
                    self.value_span(t.1, "rated_acceleration"),
                    format!(
                        "{w} rated_acceleration: must be > 0 (units/s² at rated torque), got {v}"
                    ),
                ));
            }
            m.rated_acceleration = v;
        }
        if let Some(v) = self.int(t.1, w, "following_error_window", 0, u32::MAX.into())? {
            m.following_error_window = v as u32;
        }
        if let Some(v) = self.int(t.1, w, "following_error_timeout_ms", 0, u16::MAX.into())? {
            m.following_error_timeout_ms = v as u16;
        }
        if let Some(v) = self.int(t.1, w, "enable_delay_cycles", 0, 1_000_000)? {
            m.enable_delay_cycles = v as u32;
        }
        if let Some(v) = self.float(t.1, w, "max_velocity")? {
            if v <= 0.0 {
                return Err(self.err(
                    self.value_span(t.1, "max_velocity"),
                    format!("{w} max_velocity: must be > 0 (units/s; leave it out for no limit), got {v}"),
                ));
            }
            m.max_velocity = Some(v);
        }
        if let Some(v) = self.float(t.1, w, "zero_pulse_period")? {
            if v <= 0.0 {
                return Err(self.err(
                    self.value_span(t.1, "zero_pulse_period"),
                    format!("{w} zero_pulse_period: must be > 0 (increments), got {v}"),
                ));
            }
            m.zero_pulse_period = v;
        }
        if let Some(v) = self.float(t.1, w, "torque_per_increment")? {
            if v < 0.0 {
                return Err(self.err(
                    self.value_span(t.1, "torque_per_increment"),
                    format!(
                        "{w} torque_per_increment: must be >= 0 (per mille per increment), got {v}"
                    ),
                ));
            }
            m.torque_per_increment = v;
        }
        Ok(m)
    }

    fn probe(&self, root: &dyn TableLike) -> Result<ProbeConfig, DriveError> {
        let mut p = ProbeConfig::default();
        let Some(t) = self.table(root, "probe", None)? else {
            return Ok(p);
        };
        let w = "[probe]";
        self.check_keys(t.1, w, &["rearm_requires_zero", "arm_timeout_cycles"])?;
        if let Some(v) = self.bool(t.1, w, "rearm_requires_zero")? {
            p.rearm_requires_zero = v;
        }
        if let Some(v) = self.int(t.1, w, "arm_timeout_cycles", 1, 1_000_000)? {
            p.arm_timeout_cycles = v as u32;
        }
        Ok(p)
    }

    /// `true` / `false`.
    fn bool(&self, t: &dyn TableLike, what: &str, key: &str) -> Result<Option<bool>, DriveError> {
        match t.get(key) {
            None => Ok(None),
            Some(Item::Value(Value::Boolean(b))) => Ok(Some(*b.value())),
            Some(_) => Err(self.err(
                self.value_span(t, key),
                format!("{what} {key}: expected true or false"),
            )),
        }
    }

    /// `object` (+ optional `type`) of a `[functions]` / `[idn]` entry.
    fn object_and_type(
        &self,
        f: &dyn TableLike,
        what: &str,
        kspan: Option<Range<usize>>,
    ) -> Result<(u16, u8, DataType), DriveError> {
        let object = self.opt_str(f, what, "object")?.ok_or_else(|| {
            self.err(
                kspan,
                format!("{what}: `object` is missing (e.g. \"0x6072:00\")"),
            )
        })?;
        let ospan = self.value_span(f, "object");
        let (index, sub, table_ty) = match pdo::parse_entry(&object) {
            Ok(o) => (o.0, o.1, Some(o.2)),
            Err(pdo::PdoError::UnknownObject { index, sub }) => (index, sub, None),
            Err(e) => return Err(self.err(ospan, format!("{what} object: {e}"))),
        };
        let ty = match self.opt_str(f, what, "type")? {
            Some(s) => DataType::from_name(&s).ok_or_else(|| {
                self.err(
                    self.value_span(f, "type"),
                    format!("{what} type: unknown type \"{s}\"; allowed: bool, u8, i8, u16, i16, u32, i32"),
                )
            })?,
            None => table_ty.ok_or_else(|| {
                self.err(ospan, format!("{what}: {object} is not a known CiA 402 object; add `type`"))
            })?,
        };
        Ok((index, sub, ty))
    }

    fn idns(&self, root: &dyn TableLike) -> Result<Vec<IdnMapping>, DriveError> {
        let mut out: Vec<IdnMapping> = Vec::new();
        let Some(t) = self.table(root, "idn", None)? else {
            return Ok(out);
        };
        for (key, _) in t.1.iter() {
            let kspan = self.key_span(t.1, key);
            let idn = normalize_idn(key).ok_or_else(|| {
                self.err(
                    kspan.clone(),
                    format!("[idn] \"{key}\": not a SERCOS IDN; expected S-x-yyyy or P-x-yyyy (x 0..7, yyyy 0..4095), e.g. \"S-0-0092\""),
                )
            })?;
            if out.iter().any(|m| m.idn == idn) {
                return Err(self.err(kspan, format!("[idn] \"{key}\": {idn} is given twice")));
            }
            let what = format!("[idn] \"{key}\"");
            let f = self
                .table(t.1, key, Some("[idn]"))?
                .ok_or_else(|| self.err(kspan.clone(), what.clone()))?;
            self.check_keys(f.1, &what, &["object", "type", "zero"])?;
            let (index, sub, ty) = self.object_and_type(f.1, &what, kspan)?;
            let (lo, hi) = ty.range();
            let zero = self.int(f.1, &what, "zero", lo, hi)?;
            out.push(IdnMapping {
                idn,
                index,
                sub,
                ty,
                zero,
            });
        }
        Ok(out)
    }

    fn functions(&self, root: &dyn TableLike) -> Result<Vec<DriveFunction>, DriveError> {
        let mut out = Vec::new();
        let Some(t) = self.table(root, "functions", None)? else {
            return Ok(out);
        };
        for (key, _) in t.1.iter() {
            let kspan = self.key_span(t.1, key);
            if key.is_empty()
                || !key
                    .bytes()
                    .all(|b| b.is_ascii_uppercase() || b.is_ascii_digit() || b == b'_')
            {
                return Err(self.err(
                    kspan,
                    format!("[functions] {key}: function keys are upper case letters, digits and `_` (e.g. TORQUE_LIMIT)"),
                ));
            }
            let what = format!("[functions] {key}");
            let f = self
                .table(t.1, key, Some("[functions]"))?
                .ok_or_else(|| self.err(kspan.clone(), what.clone()))?;
            self.check_keys(
                f.1,
                &what,
                &["object", "type", "unit", "scale", "min", "max", "commu"],
            )?;
            let cyclic = match self.opt_str(f.1, &what, "commu")?.as_deref() {
                None => false,
                Some(c) if c.eq_ignore_ascii_case("ACYCLIC") => false,
                Some(c) if c.eq_ignore_ascii_case("CYCLIC") => true,
                Some(c) => {
                    return Err(self.err(
                        self.value_span(f.1, "commu"),
                        format!(
                            "{what} commu = \"{c}\": allowed values are \"ACYCLIC\" and \"CYCLIC\""
                        ),
                    ))
                }
            };
            let (index, sub, ty) = self.object_and_type(f.1, &what, kspan)?;
            let unit = self.opt_str(f.1, &what, "unit")?;
            let scale = self.float(f.1, &what, "scale")?.unwrap_or(1.0);
            if scale == 0.0 {
                return Err(self.err(
                    self.value_span(f.1, "scale"),
                    format!("{what} scale: must be non-zero"),
                ));
            }
            let (lo, hi) = ty.range();
            let min = self.int(f.1, &what, "min", lo, hi)?.unwrap_or(lo);
            let max = self.int(f.1, &what, "max", lo, hi)?.unwrap_or(hi);
            if min > max {
                return Err(self.err(
                    self.value_span(f.1, "min"),
                    format!("{what}: min {min} is greater than max {max}"),
                ));
            }
            out.push(DriveFunction {
                key: key.to_string(),
                index,
                sub,
                ty,
                unit,
                scale,
                min,
                max,
                cyclic,
            });
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_parses() {
        for name in builtin_names() {
            let (_, text) = BUILTINS.iter().find(|(n, _)| n == name).unwrap();
            let def = parse(text, name).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(&def.name, name);
        }
        assert_eq!(BUILTINS.len(), BUILTIN_NAMES.len());
    }

    /// An MDP 742 terminal (Beckhoff EJ7211-0010 objects): fixed single-object PDOs, the
    /// CiA 402 roles at 0x7010 / 0x6010 / 0x6000, the touch probe words made of bits.
    #[test]
    fn device_roles_and_fixed_pdos() {
        let text = r#"
[drive]
name = "mdp"
profile = "cia402"
[device]
vendor_id = 2
product_code = "0x1C2B2852"
revision = 0x001A000A
[scaling]
increments_per_unit = 1000
[roles]
controlword = "0x7010:01"
target_position = "0x7010:05"
modes_of_operation = "0x7010:03"
statusword = "0x6010:01"
position_actual_value = "0x6000:11"
touch_probe_function = { object = "0x7001:01", bits = 16 }
[rxpdo]
pdos = ["0x1600", "0x1606", 0x1607]
fixed = true
entries = ["0x7010:01:u16", "0x7010:05:u32", "0x7001:01:bit1", "0x7001:02:bit1",
  "0x7001:03:bit2", "0x7001:05:bit1", "0x7001:06:bit1", "0x0000:00:bit2", "0x7001:09:bit1",
  "0x7001:0A:bit1", "0x7001:0B:bit2", "0x7001:0D:bit1", "0x7001:0E:bit1", "0x0000:00:bit2"]
[txpdo]
pdos = ["0x1A00", "0x1A01"]
fixed = true
entries = ["0x6000:11:u32", "0x6010:01:u16"]
"#;
        let def = parse(text, "mdp.toml").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            def.identity,
            Some(DeviceIdentity {
                vendor_id: 2,
                product_code: 0x1C2B_2852,
                revision: Some(0x001A_000A)
            })
        );
        assert_eq!(def.rx_assign.pdos, [0x1600, 0x1606, 0x1607]);
        assert!(def.rx_assign.fixed && def.tx_assign.fixed);
        let cw = def.rxpdo.find(0x6040, 0).unwrap();
        assert_eq!((cw.offset, cw.ty), (0, DataType::U16));
        let tp = def.rxpdo.find(0x60B8, 0).unwrap();
        assert_eq!((tp.offset, tp.bits), (6, 16));
        assert_eq!(def.txpdo.find(0x6064, 0).unwrap().ty, DataType::I32);
        assert_eq!(def.txpdo.find(0x6041, 0).unwrap().offset, 4);
        assert!(def.has_drive_latch() == def.txpdo.contains(0x60B9, 0));
        // The mode is an SDO object of the terminal; everything else is itself.
        assert_eq!(def.object_of(0x6060, 0), (0x7010, 3));
        assert_eq!(def.object_of(0x6065, 0), (0x6065, 0));
        assert!(crate::drive::ds402::Ds402Adapter::new(&def).is_ok());
        for (from, to, want) in [
            (
                "product_code = \"0x1C2B2852\"\n",
                "",
                "[device] product_code is missing",
            ),
            (
                "controlword = ",
                "control_word = ",
                "[roles] control_word: unknown role",
            ),
            (
                "0x1607]",
                "0x1A07]",
                "[rxpdo] pdos: expected an array of PDO indices 0x1600",
            ),
            (
                "pdos = [\"0x1A00\", \"0x1A01\"]\n",
                "",
                "[txpdo] fixed = true: name the fixed PDOs in `pdos`",
            ),
            (
                "0x7010:05\"\n",
                "0x7010:01\"\n",
                "object 0x7010:01 gives 16 bits",
            ),
        ] {
            assert!(text.contains(from), "{from}");
            let e = parse(&text.replacen(from, to, 1), "mdp.toml").unwrap_err();
            assert!(e.to_string().contains(want), "{from:?}: {e}");
        }
    }

    #[test]
    fn generic_functions_and_defaults() {
        let def = builtin("cia402-generic").unwrap();
        // FCT-C4 §7.3.2: antr.function[1] TORQUE_LIMIT, 6072 00, UNS16, LINEAR 10.0.
        let tl = def.function("TORQUE_LIMIT").unwrap();
        assert_eq!(
            (tl.index, tl.sub, tl.ty, tl.scale, tl.min, tl.max),
            (0x6072, 0, DataType::U16, 10.0, 0, 65535)
        );
        assert_eq!(tl.encode(10.0), Some(100));
        assert_eq!(tl.encode(5000.0), Some(50000));
        assert_eq!(tl.encode(6553.5), Some(65535));
        assert_eq!(tl.encode(6553.6), None);
        assert_eq!(tl.encode(-0.1), None);
        assert_eq!(tl.decode(100), 10.0);
        // antr.function[0] MON_WINDOW, 6065 00, UNS32, UNSCALED, 0 .. 4294967295.
        let mw = def.function("MON_WINDOW").unwrap();
        assert_eq!(
            (mw.index, mw.ty, mw.scale, mw.min, mw.max),
            (0x6065, DataType::U32, 1.0, 0, u32::MAX as i64)
        );
        assert_eq!(mw.encode(4294967295.0), Some(4294967295));
        assert_eq!(mw.encode(1048575.0), Some(1048575));
        assert!(def.rxpdo_defaults.is_empty());
        assert!(!def.rxpdo.contains(0x6072, 0), "torque limits are acyclic");
        assert!(def.txpdo.contains(0x6077, 0));
        assert_eq!(def.model.max_velocity, Some(1000.0));
        assert_eq!(def.model.zero_pulse_period, 10_000.0);
        assert_eq!(def.probe, ProbeConfig::default());
    }

    #[test]
    fn idn_names_and_zero_mapping() {
        for (text, norm) in [
            ("S-0-0092", Some("S-0-0092")),
            ("s-0-92", Some("S-0-0092")),
            (" S-0-0159 ", Some("S-0-0159")),
            ("P-7-4095", Some("P-7-4095")),
            ("S-8-0001", None),
            ("S-0-4096", None),
            ("S-0-", None),
            ("S-0-00-1", None),
            ("X-0-0092", None),
            ("S-0-+92", None),
            ("", None),
        ] {
            assert_eq!(normalize_idn(text).as_deref(), norm, "{text:?}");
        }
        let def = builtin("cia402-generic").unwrap();
        let tl = def.idn("s-0-92").unwrap();
        assert_eq!((tl.index, tl.sub, tl.ty), (0x6072, 0, DataType::U16));
        assert_eq!(
            (tl.encode(100), tl.encode(70_000), tl.decode(100)),
            (Some(100), None, 100)
        );
        let mw = def.idn("S-0-0159").unwrap();
        assert_eq!((mw.index, mw.ty), (0x6065, DataType::U32));
        // SERCOS "0 = monitoring off" is CiA 402 0xFFFFFFFF, both ways.
        assert_eq!(mw.encode(0), Some(0xFFFF_FFFF));
        assert_eq!(mw.decode(0xFFFF_FFFF), 0);
        assert_eq!(
            (mw.encode(1048575), mw.decode(1048575)),
            (Some(1048575), 1048575)
        );
        assert_eq!(mw.encode(-1), None);
        assert!(def.idn("S-0-0047").is_none());
        assert!(def.idn("garbage").is_none());
    }

    #[test]
    fn minimal_file_uses_defaults() {
        let def = parse(
            "[drive]\nname = \"x\"\nprofile = \"cia402\"\n[scaling]\nincrements_per_unit = 1000\n",
            "x.toml",
        )
        .unwrap();
        assert_eq!(def.model, ModelConfig::default());
        assert_eq!(def.rxpdo.len(), 9);
        assert_eq!(def.txpdo.len(), 31);
        assert!(def.functions.is_empty() && def.idns.is_empty());
        assert_eq!(def.probe, ProbeConfig::default());
    }
}
