//! The parameter registry: every P-AXIS-*, P-CHAN-* and P-MANU-* parameter named by the seeds,
//! with the ISG name path, data type, default and data range, plus [`ParamSet`], a set of values
//! for one parameter list (one axis, the channel, or manual mode).
//!
//! Sources: FCT-A2 §4 (software limit switches), FCT-C4 §8.2 (measurement), FCT-C14 §6.2
//! (workspace monitoring). Parameters the seeds only mention are taken from the ISG online
//! parameter documentation and marked so in [`ParamDef::source`].

use std::collections::BTreeMap;
use std::fmt;

/// Which parameter list a parameter belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Scope {
    /// Axis parameter list (P-AXIS-*), one per axis.
    Axis,
    /// Channel parameter list (P-CHAN-*).
    Channel,
    /// Manual-mode parameter list (P-MANU-*).
    Manual,
}

impl Scope {
    /// Lower-case name: `axis`, `channel`, `manual`.
    pub fn name(self) -> &'static str {
        match self {
            Scope::Axis => "axis",
            Scope::Channel => "channel",
            Scope::Manual => "manual",
        }
    }

    /// The machine-file section that holds this list: `[[axis]]`, `[channel]`, `[manual]`.
    pub fn section(self) -> &'static str {
        match self {
            Scope::Axis => "[[axis]]",
            Scope::Channel => "[channel]",
            Scope::Manual => "[manual]",
        }
    }

    /// The ID prefix of the list: `P-AXIS`, `P-CHAN`, `P-MANU`.
    pub fn id_prefix(self) -> &'static str {
        match self {
            Scope::Axis => "P-AXIS",
            Scope::Channel => "P-CHAN",
            Scope::Manual => "P-MANU",
        }
    }

    fn describe(self) -> &'static str {
        match self {
            Scope::Axis => "an axis parameter",
            Scope::Channel => "a channel parameter",
            Scope::Manual => "a manual-mode parameter",
        }
    }

    fn place(self) -> &'static str {
        match self {
            Scope::Axis => "an [[axis]] table (axis parameter list)",
            Scope::Channel => "[channel] (channel parameter list)",
            Scope::Manual => "[manual] (manual-mode parameter list)",
        }
    }
}

impl fmt::Display for Scope {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// ISG data type of a parameter ("Data type" row of the seeds' parameter tables).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ParamType {
    /// BOOLEAN: 0/1.
    Boolean,
    /// UNS08.
    Uns08,
    /// UNS16.
    Uns16,
    /// UNS32.
    Uns32,
    /// SGN08.
    Sgn08,
    /// SGN16.
    Sgn16,
    /// SGN32.
    Sgn32,
    /// STRING.
    Str,
}

impl ParamType {
    /// The ISG spelling: `BOOLEAN`, `UNS08`, …, `STRING`.
    pub fn name(self) -> &'static str {
        match self {
            ParamType::Boolean => "BOOLEAN",
            ParamType::Uns08 => "UNS08",
            ParamType::Uns16 => "UNS16",
            ParamType::Uns32 => "UNS32",
            ParamType::Sgn08 => "SGN08",
            ParamType::Sgn16 => "SGN16",
            ParamType::Sgn32 => "SGN32",
            ParamType::Str => "STRING",
        }
    }

    /// Representable range of an integer type (`None` for STRING).
    pub fn bounds(self) -> Option<(i64, i64)> {
        match self {
            ParamType::Boolean => Some((0, 1)),
            ParamType::Uns08 => Some((0, u8::MAX as i64)),
            ParamType::Uns16 => Some((0, u16::MAX as i64)),
            ParamType::Uns32 => Some((0, u32::MAX as i64)),
            ParamType::Sgn08 => Some((i8::MIN as i64, i8::MAX as i64)),
            ParamType::Sgn16 => Some((i16::MIN as i64, i16::MAX as i64)),
            ParamType::Sgn32 => Some((i32::MIN as i64, i32::MAX as i64)),
            ParamType::Str => None,
        }
    }
}

impl fmt::Display for ParamType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Default value of a parameter ("Default value" row).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DefaultValue {
    /// Integer (also BOOLEAN 0/1).
    Int(i64),
    /// String; the seeds' "blank string" default is `""`.
    Text(&'static str),
}

/// Machine-checkable data range of a parameter. The seeds' own wording is in
/// [`ParamDef::range_text`]; ranges that refer to other parameters (e.g. `swe_neg < P-AXIS-00178`)
/// are checked by [`ParamSet::check_cross`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Range {
    /// Inclusive integer range (already intersected with the type's bounds).
    Int {
        /// Smallest accepted value.
        min: i64,
        /// Largest accepted value.
        max: i64,
    },
    /// One of these words (canonical upper case). Parameters whose default is the seeds'
    /// "blank string" (P-AXIS-00516, P-AXIS-00518: "not defined", the old parameters apply)
    /// also accept the empty string.
    Choice(&'static [&'static str]),
    /// Any text.
    AnyText,
}

impl Range {
    /// Whether `v` lies in an integer range (`false` for text ranges).
    pub fn contains_int(&self, v: i64) -> bool {
        matches!(*self, Range::Int { min, max } if min <= v && v <= max)
    }

    /// The canonical spelling of `s` if it is one of the choices (case-insensitive match).
    pub fn canonical_text(&self, s: &str) -> Option<&'static str> {
        match *self {
            Range::Choice(words) => words.iter().copied().find(|w| w.eq_ignore_ascii_case(s)),
            _ => None,
        }
    }
}

/// One parameter definition.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ParamDef {
    /// ISG identifier, e.g. `P-AXIS-00177`.
    pub id: &'static str,
    /// ISG name path exactly as ISG writes it, e.g. `kenngr.swe_neg`, `getriebe[i].dynamik.a_max`;
    /// channel and manual parameters are bare names (`messtyp`, `move_limit_warning`).
    pub path: &'static str,
    /// Parameter list.
    pub scope: Scope,
    /// Data type.
    pub ty: ParamType,
    /// Default value.
    pub default: DefaultValue,
    /// Machine-checkable range.
    pub range: Range,
    /// The data range as the source writes it (verbatim where the source gives a formula).
    pub range_text: &'static str,
    /// Dimension, e.g. `T: 0.1µm, R: 0.0001°`.
    pub dimension: &'static str,
    /// Short title.
    pub title: &'static str,
    /// Where the definition comes from: `seed NNN §x.y`, `ISG online parameter docs (not in
    /// seeds)`, or `project assumption`.
    pub source: &'static str,
}

impl ParamDef {
    /// Whether the parameter holds text (STRING) rather than an integer.
    pub fn is_text(&self) -> bool {
        self.ty == ParamType::Str
    }

    /// The default as a [`ParamValue`].
    pub fn default_value(&self) -> ParamValue {
        match self.default {
            DefaultValue::Int(v) => ParamValue::Int(v),
            DefaultValue::Text(s) => ParamValue::Text(s.to_string()),
        }
    }

    /// Parse and range-check a raw value (surrounding whitespace and quotes are stripped).
    /// BOOLEAN accepts `0`, `1`, `true`, `false` in any case; integers are decimal or `0x` hex;
    /// STRING choices match case-insensitively and are stored in canonical upper case.
    pub fn parse_value(
        &'static self,
        raw: &str,
        origin: &Origin,
    ) -> Result<ParamValue, ParamError> {
        let text = strip_quotes(raw.trim());
        if self.is_text() {
            let canonical = match self.range {
                Range::AnyText => return Ok(ParamValue::Text(text.to_string())),
                _ if text.is_empty() && self.default == DefaultValue::Text("") => Some(""),
                _ => self
                    .range
                    .canonical_text(text)
                    .or_else(|| choice_alias(self, text)),
            };
            return match canonical {
                Some(c) => Ok(ParamValue::Text(c.to_string())),
                None => Err(ParamError::OutOfRange {
                    origin: origin.clone(),
                    def: self,
                    value: text.to_string(),
                }),
            };
        }
        let number = if self.ty == ParamType::Boolean && text.eq_ignore_ascii_case("true") {
            Some(1)
        } else if self.ty == ParamType::Boolean && text.eq_ignore_ascii_case("false") {
            Some(0)
        } else {
            parse_int(text)
        };
        let Some(number) = number else {
            return Err(ParamError::InvalidValue {
                origin: origin.clone(),
                def: self,
                value: text.to_string(),
            });
        };
        match i64::try_from(number) {
            Ok(v) if self.accepts_int(v) => Ok(ParamValue::Int(v)),
            _ => Err(ParamError::OutOfRange {
                origin: origin.clone(),
                def: self,
                value: text.to_string(),
            }),
        }
    }

    /// Whether an integer value is accepted (range, type bounds and, for the few enumerated
    /// integer parameters, the listed values).
    pub fn accepts_int(&self, v: i64) -> bool {
        let in_type = self.ty.bounds().is_some_and(|(lo, hi)| lo <= v && v <= hi);
        let listed = match discrete_values(self.id) {
            Some(vals) => vals.contains(&v),
            None => true,
        };
        in_type && listed && self.range.contains_int(v)
    }
}

/// A parameter value.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum ParamValue {
    /// Integer (also BOOLEAN 0/1).
    Int(i64),
    /// Text (canonical upper case for choices).
    Text(String),
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamValue::Int(v) => write!(f, "{v}"),
            ParamValue::Text(s) => f.write_str(s),
        }
    }
}

/// Where a value came from: a file and a 1-based line (`line == 0`: no line, e.g. `--set`).
#[derive(Debug, Clone, PartialEq, Eq, Hash, Default)]
pub struct Origin {
    /// File name as given by the user (or `--set`, `<api>`, `<default>`).
    pub file: String,
    /// 1-based line; 0 = no line.
    pub line: usize,
}

impl Origin {
    /// An origin.
    pub fn new(file: impl Into<String>, line: usize) -> Self {
        Origin {
            file: file.into(),
            line,
        }
    }

    /// The origin of values set through the API ([`ParamSet::set_int`]).
    pub fn api() -> Self {
        Origin::new("<api>", 0)
    }
}

impl fmt::Display for Origin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            f.write_str(&self.file)
        } else {
            write!(f, "{}:{}", self.file, self.line)
        }
    }
}

/// Errors of the parameter layer. Every message names the file and line, the key, and the
/// source's range text where a value is rejected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParamError {
    /// The key is neither a known ID nor a known name path.
    #[error("{origin}: unknown parameter '{key}'{}", did_you_mean(.suggestion))]
    UnknownParameter {
        /// Where.
        origin: Origin,
        /// The key as written.
        key: String,
        /// The closest known key, formatted as `'kenngr.swe_neg' (P-AXIS-00177)`.
        suggestion: Option<String>,
    },
    /// The parameter belongs to another list.
    #[error("{origin}: {} {} is {} and cannot be set in {}; set it in {}",
        .def.id, .def.path, .def.scope.describe(), .found.place(), .def.scope.place())]
    WrongScope {
        /// Where.
        origin: Origin,
        /// The parameter.
        def: &'static ParamDef,
        /// The list it was written into.
        found: Scope,
    },
    /// The value does not parse as the parameter's type.
    #[error("{origin}: {} {} = {value} is not a valid {} value ({}: {})",
        .def.id, .def.path, .def.ty, range_label(.def), .def.range_text)]
    InvalidValue {
        /// Where.
        origin: Origin,
        /// The parameter.
        def: &'static ParamDef,
        /// The value as written (quotes stripped).
        value: String,
    },
    /// The value parses but lies outside the data range.
    #[error("{origin}: {} {} = {value} is out of range ({}: {})",
        .def.id, .def.path, range_label(.def), .def.range_text)]
    OutOfRange {
        /// Where.
        origin: Origin,
        /// The parameter.
        def: &'static ParamDef,
        /// The value as written (quotes stripped).
        value: String,
    },
    /// A range that refers to another parameter is violated (e.g. swe_neg < swe_pos).
    #[error("{origin}{context}: {} {} = {value} must be {requirement}", .def.id, .def.path)]
    CrossCheck {
        /// Where (the last assignment of a parameter involved).
        origin: Origin,
        /// Set label, e.g. ` (axis X)`, or empty.
        context: String,
        /// The parameter whose range is violated.
        def: &'static ParamDef,
        /// Its value.
        value: i64,
        /// The violated requirement, e.g. `< P-AXIS-00178 kenngr.swe_pos = 4`.
        requirement: String,
    },
    /// A file could not be read.
    #[error("{file}: cannot read file: {message}")]
    Io {
        /// The file.
        file: String,
        /// The OS error text.
        message: String,
    },
    /// TOML syntax error in a machine file.
    #[error("{origin}: invalid TOML: {message}")]
    Toml {
        /// Where.
        origin: Origin,
        /// What the TOML parser said.
        message: String,
    },
    /// Any other machine-file or `--set` problem (unknown table, bad axis name, …).
    #[error("{origin}: {message}")]
    Config {
        /// Where.
        origin: Origin,
        /// What is wrong and what was expected.
        message: String,
    },
    /// `--set` of an axis parameter without an axis prefix.
    #[error("{origin}: {} {} is an axis parameter; prefix it with the axis name, e.g. '{example}' (axes: {axes})",
        .def.id, .def.path)]
    MissingAxisPrefix {
        /// Where.
        origin: Origin,
        /// The parameter.
        def: &'static ParamDef,
        /// A corrected assignment.
        example: String,
        /// The machine's axes, comma separated.
        axes: String,
    },
    /// `--set` with an axis prefix the machine does not have.
    #[error("{origin}: unknown axis '{axis}' in '{assignment}'; the machine has axes {axes}")]
    UnknownAxis {
        /// Where.
        origin: Origin,
        /// The prefix as written.
        axis: String,
        /// The whole assignment.
        assignment: String,
        /// The machine's axes, comma separated.
        axes: String,
    },
}

fn did_you_mean(suggestion: &Option<String>) -> String {
    match suggestion {
        Some(s) => format!("; did you mean {s}?"),
        None => String::new(),
    }
}

fn range_label(def: &ParamDef) -> &'static str {
    if def.source.starts_with("seed") {
        "seed"
    } else if def.source.starts_with("ISG") {
        "ISG docs"
    } else {
        "project"
    }
}

// ---------------------------------------------------------------------------------------------
// The table
// ---------------------------------------------------------------------------------------------

const U08: i64 = u8::MAX as i64;
const U16: i64 = u16::MAX as i64;
const U32: i64 = u32::MAX as i64;
const S16_MIN: i64 = i16::MIN as i64;
const S16_MAX: i64 = i16::MAX as i64;
const S32_MIN: i64 = i32::MIN as i64;
const S32_MAX: i64 = i32::MAX as i64;
const BOOL: Range = Range::Int { min: 0, max: 1 };

const fn ri(min: i64, max: i64) -> Range {
    Range::Int { min, max }
}
const fn di(v: i64) -> DefaultValue {
    DefaultValue::Int(v)
}
const fn dt(s: &'static str) -> DefaultValue {
    DefaultValue::Text(s)
}

macro_rules! registry_table {
    ($( $name:ident = $id:literal, $path:literal, $scope:ident, $ty:ident, $default:expr,
        $range:expr, $rt:literal, $dim:literal, $title:literal, $src:literal; )*) => {
        /// Parameter IDs as constants, one per registry entry, so code names parameters without
        /// typos: `params.int(id::SWE_NEG)`.
        pub mod id {
            $(
                #[doc = concat!($id, " `", $path, "` (", $src, "): ", $title, ".")]
                pub const $name: &str = $id;
            )*
        }

        static REGISTRY: &[ParamDef] = &[
            $( ParamDef {
                id: $id,
                path: $path,
                scope: Scope::$scope,
                ty: ParamType::$ty,
                default: $default,
                range: $range,
                range_text: $rt,
                dimension: $dim,
                title: $title,
                source: $src,
            }, )*
        ];
    };
}

// Sorted by ID (binary search in `find`). Ranges whose seed text excludes the seed's own default
// (e.g. `0 < min_time` with default 0, where the description says 0 selects a fallback) are
// widened to include the default; see docs/parameters.md.
registry_table! {
    A_BESCHL = "P-AXIS-00001", "getriebe[i].slope_profil.a_beschl", Axis, Uns32, di(1000),
        ri(1, U32), "1 ≤ a_beschl ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Acceleration at machining feed (non-linear slope)",
        "ISG online parameter docs (not in seeds)";
    A_BREMS = "P-AXIS-00002", "getriebe[i].slope_profil.a_brems", Axis, Uns32, di(1000),
        ri(1, U32), "1 ≤ a_brems ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Deceleration at machining feed (non-linear slope)",
        "ISG online parameter docs (not in seeds)";
    A_EMERGENCY = "P-AXIS-00003", "getriebe[i].dynamik.a_emergency", Axis, Uns32, di(0),
        ri(0, U32), "1 ≤ a_emergency ≤ 2*P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Deceleration for an emergency stop (0: P-AXIS-00008 is used)",
        "ISG online parameter docs (not in seeds)";
    A_GRENZ = "P-AXIS-00004", "getriebe[i].slope_profil.a_grenz", Axis, Uns32, di(1000),
        ri(1, U32), "1 ≤ a_grenz ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Acceleration at rapid movement (non-linear slope)",
        "ISG online parameter docs (not in seeds)";
    A_GRENZ_STUFE_1 = "P-AXIS-00005", "getriebe[i].lslope_profil.a_grenz_stufe_1", Axis, Uns32,
        di(1000), ri(1, U32), "1 ≤ a_grenz_stufe_1 ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Acceleration of step 1 in rapid mode (linear slope)",
        "ISG online parameter docs (not in seeds)";
    A_GRENZ_STUFE_2 = "P-AXIS-00006", "getriebe[i].lslope_profil.a_grenz_stufe_2", Axis, Uns32,
        di(1000), ri(1, U32), "1 ≤ a_grenz_stufe_2 ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Acceleration of step 2 in rapid mode (linear slope)",
        "ISG online parameter docs (not in seeds)";
    A_MAX = "P-AXIS-00008", "getriebe[i].dynamik.a_max", Axis, Uns32, di(1000),
        ri(1, 100_000_000), "1 ≤ a_max ≤ 100000000", "T: mm/s², R,S: °/s²",
        "Maximum permissible axis acceleration (bound of the a_* ranges)",
        "ISG online parameter docs (not in seeds)";
    A_STUFE_1 = "P-AXIS-00011", "getriebe[i].lslope_profil.a_stufe_1", Axis, Uns32, di(1000),
        ri(1, U32), "1 ≤ a_stufe_1 ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Acceleration of step 1 (linear slope)",
        "ISG online parameter docs (not in seeds)";
    A_STUFE_2 = "P-AXIS-00012", "getriebe[i].lslope_profil.a_stufe_2", Axis, Uns32, di(1000),
        ri(1, U32), "1 ≤ a_stufe_2 ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Acceleration of step 2 (linear slope)",
        "ISG online parameter docs (not in seeds)";
    ABS_POS_GUELTIG = "P-AXIS-00014", "kenngr.abs_pos_gueltig", Axis, Boolean, di(0), BOOL,
        "0/1", "----", "Identification code for absolute path measurement system",
        "seed 001 §4.3";
    ACHS_MODE = "P-AXIS-00015", "kenngr.achs_mode", Axis, Uns32, di(0x1), ri(1, U32),
        "0x00000001 - 0x10000000", "----",
        "Axis mode, bit mask (0x1 ACHSMODE_LINEAR, 0x4 ACHSMODE_MODULO)",
        "ISG online parameter docs (not in seeds)";
    ACHS_TYP = "P-AXIS-00018", "kenngr.achs_typ", Axis, Str, dt("ACHSTYP_TRANSLATOR"),
        Range::Choice(&["ACHSTYP_TRANSLATOR", "ACHSTYP_ROTATOR", "ACHSTYP_SPINDEL"]),
        "Linear axis (ACHSTYP_TRANSLATOR): 0x0001, Rotary axis (ACHSTYP_ROTATOR): 0x0002, Spindle (ACHSTYP_SPINDEL): 0x0004",
        "----", "Axis type (linear axis, rotary axis, spindle)",
        "ISG online parameter docs (not in seeds)";
    ANTR_TYP = "P-AXIS-00020", "kenngr.antr_typ", Axis, Uns16, di(4), ri(1, 32),
        "1: Conventional, 2: SERCOS, 3: PROFIDRIVE MC, 4: Drive simulation, 5: Beckhoff Lightbus, 6: +-10V over field bus (terminal), 7: RT Ethernet, 8: CANopen, 16: Virtual axis, 32: CAN bus",
        "----", "Drive type", "ISG online parameter docs (not in seeds)";
    LSLOPE_A_FEEDH = "P-AXIS-00024", "getriebe[i].lslope_profil.a_feedh", Axis, Uns32, di(0),
        ri(0, U32), "0 ≤ a_feedh ≤ P-AXIS-00008", "T: mm/s², R: °/s²",
        "Deceleration for feedhold (linear slope; 0: minimum of P-AXIS-00005/00006)",
        "ISG online parameter docs (not in seeds)";
    SLOPE_A_FEEDH = "P-AXIS-00053", "getriebe[i].slope_profil.a_feedh", Axis, Uns32, di(0),
        ri(0, U32), "1 ≤ a_feedh ≤ P-AXIS-00008", "T: mm/s², R: °/s²",
        "Deceleration at feedhold (non-linear slope; 0: P-AXIS-00004 is used)",
        "ISG online parameter docs (not in seeds)";
    ECHTZEIT_BIT_NR = "P-AXIS-00060", "kenngr.echtzeit_bit_nr", Axis, Uns08, di(0), ri(0, 2),
        "0 ≤ echtzeit_bit_nr ≤ 2", "----",
        "SERCOS real-time status/control bits used for measurement", "seed 004 §8.2.2";
    TR_FEEDH = "P-AXIS-00081", "getriebe[i].slope_profil.tr_feedh", Axis, Uns32, di(0),
        ri(0, U32), "P-AXIS-00201 ≤ tr_feedh ≤ MAX(UNS32)", "T: µs, R: µs",
        "Ramp time at feedhold (non-linear slope; 0: P-AXIS-00200 is used)",
        "ISG online parameter docs (not in seeds)";
    HUB_MESSTASTER = "P-AXIS-00086", "kenngr.hub_messtaster", Axis, Uns32, di(50000),
        ri(0, U32), "0 ≤ hub_messtaster ≤ MAX(UNS32)", "T: 0.1µm, R: 0.0001°",
        "Probe stroke for measurement types 2 and 4", "seed 004 §8.2.2";
    MASK_MESS_1 = "P-AXIS-00106", "lr_hw[i].mask_mess_1", Axis, Uns16, di(0x80), ri(0x40, 0x80),
        "0x0040: Status bit 1, 0x0080: Status bit 2", "----",
        "SERCOS status bit for measurement (used when P-AXIS-00060 = 0)",
        "ISG online parameter docs (not in seeds)";
    MESS_NEG_FLANKE = "P-AXIS-00113", "kenngr.mess_neg_flanke", Axis, Boolean, di(0), BOOL,
        "0: Latch at positive edge of pulse, 1: Latch at negative edge of pulse", "----",
        "Probing signal edge (old, replaced by P-AXIS-00518)", "seed 004 §8.2.4";
    MESS_OFFSET = "P-AXIS-00114", "kenngr.mess_offset", Axis, Uns32, di(0), ri(0, U32),
        "0 ≤ mess_offset ≤ MAX(UNS32)", "T: 0.1µm, R: 0.0001°",
        "Measurement travel offset for measurement type 2 (old, replaced by P-AXIS-00467; used in type 2 when P-AXIS-00467 is not set)",
        "seed 004 §8.2.2 (P-AXIS-00467 remarks); name and range: ISG online parameter docs";
    MESS_SIGNAL_ACHS_STEUER = "P-AXIS-00115", "kenngr.mess_signal_achs_steuer", Axis, Boolean,
        di(0), BOOL, "0/1", "----",
        "Measurement signal via axis-specific control bit mask (old)", "seed 004 §8.2.4";
    MESS_SIGNAL_SERCOS = "P-AXIS-00116", "kenngr.mess_signal_sercos", Axis, Boolean, di(0), BOOL,
        "0: Request from a measurement probe, 1: Usage of measurement function supplied by the drive (SERCOS measurement)",
        "----", "Measurement with SERCOS drives (old)", "seed 004 §8.2.4";
    MESS_SIGNAL_TASTER = "P-AXIS-00117", "kenngr.mess_signal_taster", Axis, Boolean, di(0), BOOL,
        "0/1", "----", "Measurement signal from hardware interface (old)", "seed 004 §8.2.4";
    MESSACHSE = "P-AXIS-00118", "kenngr.messachse", Axis, Boolean, di(0), BOOL, "0/1", "----",
        "Define axis as measurement axis", "seed 004 §8.2.2";
    MODULOO = "P-AXIS-00126", "getriebe[i].moduloo", Axis, Sgn32, di(3_600_000),
        ri(S32_MIN + 1, S32_MAX), "modulou < moduloo ≤ MAX(SGN32)", "R,S: 0.0001°",
        "Upper modulo limit (rotary axes with ACHSMODE_MODULO, P-AXIS-00015)",
        "ISG online parameter docs (not in seeds)";
    MODULOU = "P-AXIS-00127", "getriebe[i].modulou", Axis, Sgn32, di(0),
        ri(S32_MIN, S32_MAX - 1), "MIN(SGN32) ≤ modulou < moduloo", "R,S: 0.0001°",
        "Lower modulo limit (rotary axes with ACHSMODE_MODULO, P-AXIS-00015)",
        "ISG online parameter docs (not in seeds)";
    OFFSETGRENZE_NEG = "P-AXIS-00137", "handbetrieb.offsetgrenze_neg", Axis, Sgn32, di(-1_000_000),
        ri(S32_MIN, 0), "MIN(SGN32) ≤ offsetgrenze_neg ≤ 0", "T: 0.1µm, R: 0.0001°",
        "Relative negative offset limit in manual mode", "seed 001 §4.3";
    OFFSETGRENZE_POS = "P-AXIS-00138", "handbetrieb.offsetgrenze_pos", Axis, Sgn32, di(1_000_000),
        ri(0, S32_MAX), "0 ≤ offsetgrenze_pos ≤ MAX(SGN32)", "T: 0.1µm, R: 0.0001°",
        "Relative positive offset limit in manual mode", "seed 001 §4.3";
    SLEP_MAX = "P-AXIS-00168", "getriebe[i].slep_max", Axis, Sgn32, di(100_000), ri(0, S32_MAX),
        "0 ≤ slep_max ≤ MAX(SGN32) (0: CNC position lag monitoring off)", "T: 0.1 µm, R,S: 0.0001°",
        "Maximum position lag (CNC position lag monitoring; off during measurement type 7)",
        "ISG online parameter docs (not in seeds); needed by seed 004 §7.3.1 'disable position lag monitoring in the position controller'";
    SWE_NEG = "P-AXIS-00177", "kenngr.swe_neg", Axis, Sgn32, di(-100_000_000),
        ri(S32_MIN + 1, S32_MAX), "MIN(SGN32) < swe_neg < P-AXIS-00178", "T: 0.1µm, R: 0.0001°",
        "Negative software limit switch", "seed 001 §4.3, seed 000 §6.2";
    SWE_POS = "P-AXIS-00178", "kenngr.swe_pos", Axis, Sgn32, di(100_000_000),
        ri(S32_MIN, S32_MAX - 1), "P-AXIS-00177 < swe_pos < MAX(SGN32)", "T: 0.1µm, R,S: 0.0001°",
        "Positive software limit switch", "seed 001 §4.3, seed 000 §6.2";
    SWE_TOLERANZ = "P-AXIS-00179", "kenngr.swe_toleranz", Axis, Uns32, di(1000), ri(0, U32),
        "0 ≤ swe_toleranz ≤ MAX(UNS32)", "T: 0.1µm, R: 0.0001°",
        "Tolerance range for software limit switch", "seed 001 §4.3";
    VB_MAX = "P-AXIS-00212", "getriebe[i].dynamik.vb_max", Axis, Uns32, di(200_000),
        ri(1, 2_000_000_000), "1 ≤ vb_max ≤ 2000000000", "T: µm/s, R,S: 0.001°/s",
        "Maximum permissible axis velocity", "ISG online parameter docs (not in seeds)";
    VB_MESSEN = "P-AXIS-00215", "kenngr.vb_messen", Axis, Uns32, di(16666), ri(1, U32),
        "1 ≤ vb_messen ≤ P-AXIS-00212", "T: µm/s, R,S: 0.001°/s",
        "Measurement speed for measurement type 2", "seed 004 §8.2.2";
    PROBING_SIGNAL_VIA_PLC = "P-AXIS-00257", "kenngr.probing_signal_via_plc", Axis, Boolean,
        di(0), BOOL, "0/1", "----", "Measurement signal via HLI control unit (old)",
        "seed 004 §8.2.4";
    MEAS_SIGNAL_DRIVE = "P-AXIS-00269", "kenngr.meas_signal_drive", Axis, Boolean, di(0), BOOL,
        "0/1", "----", "Measurement signal from the drive (old, replaced by P-AXIS-00516)",
        "ISG online parameter docs (not in seeds); path also in seed 004 §8.2.2";
    D_GRENZ_STUFE_1 = "P-AXIS-00280", "getriebe[i].lslope_profil.d_grenz_stufe_1", Axis, Uns32,
        di(0), ri(0, U32), "1 ≤ d_grenz_stufe_1 ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Deceleration of step 1 in rapid mode (linear slope; 0: P-AXIS-00005 is used)",
        "ISG online parameter docs (not in seeds)";
    D_GRENZ_STUFE_2 = "P-AXIS-00281", "getriebe[i].lslope_profil.d_grenz_stufe_2", Axis, Uns32,
        di(0), ri(0, U32), "1 ≤ d_grenz_stufe_2 ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Deceleration of step 2 in rapid mode (linear slope; 0: P-AXIS-00006 is used)",
        "ISG online parameter docs (not in seeds)";
    D_STUFE_1 = "P-AXIS-00282", "getriebe[i].lslope_profil.d_stufe_1", Axis, Uns32, di(0),
        ri(0, U32), "1 ≤ d_stufe_1 ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Deceleration of step 1 (linear slope; 0: P-AXIS-00011 is used)",
        "ISG online parameter docs (not in seeds)";
    D_STUFE_2 = "P-AXIS-00283", "getriebe[i].lslope_profil.d_stufe_2", Axis, Uns32, di(0),
        ri(0, U32), "1 ≤ d_stufe_2 ≤ P-AXIS-00008", "T: mm/s², R,S: °/s²",
        "Deceleration of step 2 (linear slope; 0: P-AXIS-00012 is used)",
        "ISG online parameter docs (not in seeds)";
    CANOPEN_PROBING_INPUT_NUMBER = "P-AXIS-00295", "antr.canopen.probing_input_number", Axis,
        Uns16, di(0), ri(0, 2), "1, 2", "----",
        "Number of probing input, CANopen (old, replaced by P-AXIS-00430 / P-AXIS-00517)",
        "ISG online parameter docs (not in seeds)";
    MEAS_SIGNAL_FIXED_STOP = "P-AXIS-00330", "kenngr.meas_signal_fixed_stop", Axis, Boolean,
        di(0), BOOL, "0/1", "----", "Measurement with movement to a fixed stop (old)",
        "seed 004 §8.2.4";
    FIXED_STOP_POS_LAG_LIMIT = "P-AXIS-00331", "kenngr.fixed_stop_pos_lag_limit", Axis, Uns32,
        di(0), ri(0, U32), "0 ≤ fixed_stop_pos_lag_limit ≤ MAX(UNS32)", "T: 0.1µm, R: 0.0001°",
        "Limit for position lag during movement to a fixed stop (old)", "seed 004 §8.2.2";
    FIXED_STOP_NBR_CYCLES = "P-AXIS-00332", "kenngr.fixed_stop_nbr_cycles", Axis, Uns16, di(0),
        ri(0, U16 - 1), "0 < fixed_stop_nbr_cycles < MAX(UNS16)",
        "T, R: number of interpolation cycles",
        "Number of position control cycles during movement to a fixed stop (old)",
        "seed 004 §8.2.2";
    PROBING_INPUT_NBR = "P-AXIS-00430", "antr.probing_input_nbr", Axis, Uns08, di(0), ri(0, 2),
        "0, 1, 2", "----", "Number of probing input in drive (old, replaced by P-AXIS-00517)",
        "ISG online parameter docs (not in seeds)";
    PROBING_OFFSET = "P-AXIS-00467", "kenngr.probing_offset", Axis, Uns32, di(0), ri(0, U32),
        "0 ≤ probing_offset ≤ MAX(UNS32)", "T: 0.1µm, R: 0.0001°",
        "Measurement travel offset for all measurement types", "seed 004 §8.2.2";
    ACS_LIMIT_NEG = "P-AXIS-00492", "handbetrieb.acs_limit_neg", Axis, Sgn32, di(0),
        ri(S32_MIN, S32_MAX), "P-AXIS-00177 ≤ acs_limit_neg ≤ P-AXIS-00178",
        "T: 0.1µm, R: 0.0001°", "Absolute negative ACS movement limit in manual mode (0: inactive)",
        "ISG online parameter docs (not in seeds)";
    ACS_LIMIT_POS = "P-AXIS-00493", "handbetrieb.acs_limit_pos", Axis, Sgn32, di(0),
        ri(S32_MIN, S32_MAX), "P-AXIS-00177 ≤ acs_limit_pos ≤ P-AXIS-00178",
        "T: 0.1µm, R: 0.0001°", "Absolute positive ACS movement limit in manual mode (0: inactive)",
        "ISG online parameter docs (not in seeds)";
    MEASURE_SIGNAL = "P-AXIS-00516", "kenngr.measure.signal", Axis, Str, dt(""),
        Range::Choice(&["DRIVE_TYPE_DEFAULT", "PLC", "FIXED_STOP", "DRIVE", "PLC_EXT_LATCH_CONTROL",
            "PLC_FIRST_EVENT", "PLC_TIMESTAMP", "EXT_PROBE_WITH_DRIVE"]),
        "DRIVE_TYPE_DEFAULT, PLC, FIXED_STOP, DRIVE, PLC_EXT_LATCH_CONTROL, PLC_FIRST_EVENT, PLC_TIMESTAMP, EXT_PROBE_WITH_DRIVE",
        "----", "Measurement method (probing signal source)", "seed 004 §8.2.2";
    MEASURE_INPUT = "P-AXIS-00517", "kenngr.measure.input", Axis, Uns08, di(0), ri(0, U08),
        "Valid probing inputs dependent on drive type and probing signal source", "----",
        "Number of probing input", "seed 004 §8.2.2";
    MEASURE_EDGE = "P-AXIS-00518", "kenngr.measure.edge", Axis, Str, dt(""),
        Range::Choice(&["POS", "NEG"]),
        "POS: Latching if positive measured signal edge, NEG: Latching if negative measured signal edge",
        "----", "Probing signal edge", "seed 004 §8.2.2";
    CHECK_POS_COMMAND_LIMIT = "P-AXIS-00520", "lr_param.check_pos_command_limit", Axis, Boolean,
        di(0), BOOL, "0/1", "T: ----",
        "Activation of limit switch monitoring of the positive limit switch", "seed 001 §4.3";
    CHECK_NEG_COMMAND_LIMIT = "P-AXIS-00521", "lr_param.check_neg_command_limit", Axis, Boolean,
        di(0), BOOL, "0/1", "T: ----",
        "Activation of limit switch monitoring of the negative limit switch", "seed 001 §4.3";
    SWE_BEHAVIOUR = "P-AXIS-00554", "kenngr.swe_behaviour", Axis, Str, dt("ERROR"),
        Range::Choice(&["ERROR", "ERROR_LR", "WARNING"]), "ERROR, ERROR_LR, WARNING", "----",
        "Behaviour of software limit switches", "seed 001 §4.3";
    PROBING_TRIGGER_SOURCE = "P-AXIS-00702", "antr.canopen.probing_trigger_source", Axis, Str,
        dt("DEFAULT"), Range::Choice(&["DEFAULT", "CNC_DEFINED", "DRIVE_DEFINED"]),
        "\"DEFAULT\" \"CNC_DEFINED\" \"DRIVE_DEFINED\"", "----",
        "Trigger source for probing in the drive (object 0x60D0)",
        "seed 004 §6.4; default from ISG online parameter docs (not in seeds)";
    SWE_CHECK = "P-AXIS-00705", "kenngr.swe_check", Axis, Sgn08, di(-1), ri(-1, 1),
        "-1: dependent on axis type and axis mode (default), 0: switch off software limit monitoring, 1: switch on software limit monitoring",
        "----", "Switching software limit monitoring off / on", "seed 001 §4.3";
    FS_POS_LAG_LIMIT = "P-AXIS-00769", "antr.fixed_stop.detect.pos_lag_limit", Axis, Sgn32, di(-1),
        ri(S32_MIN + 1, S32_MAX - 1), "MIN(SGN32) < P-AXIS-00769 < MAX(SGN32)",
        "T: 0.1µm, R: 0.0001°", "Position lag limit for fixed stop detection",
        "ISG online parameter docs (not in seeds)";
    FS_MIN_TIME = "P-AXIS-00770", "antr.fixed_stop.detect.min_time", Axis, Uns32, di(0),
        ri(0, U32 - 1), "0 < P-AXIS-00770 < MAX(UNS32)", "T: µs, R: µs",
        "Minimum time for fixed stop detection (0: P-AXIS-00332 is used)",
        "ISG online parameter docs (not in seeds)";
    FS_START_DISTANCE = "P-AXIS-00771", "antr.fixed_stop.detect.start_distance", Axis, Sgn32,
        di(-1), ri(S32_MIN + 1, S32_MAX - 1), "0 < P-AXIS-00771 < MAX(SGN32)",
        "T: 0.1µm, R: 0.0001°", "Minimum path to activate fixed stop detection (< 0: 0)",
        "ISG online parameter docs (not in seeds)";
    FS_START_DISTANCE_PER_MILLE = "P-AXIS-00772", "antr.fixed_stop.detect.start_distance_per_mille",
        Axis, Sgn16, di(-1), ri(S16_MIN + 1, S16_MAX), "MIN(SGN16) < P-AXIS-00772 ≤ 1000",
        "T, R: 0.1%", "Minimum path to activate fixed stop detection, per mille of block length",
        "ISG online parameter docs (not in seeds)";
    FS_MAX_DELTA_POSITION_WINDOW = "P-AXIS-00773", "antr.fixed_stop.detect.max_delta_position_window",
        Axis, Sgn32, di(-1), ri(S32_MIN + 1, S32_MAX), "MIN(SGN32) < P-AXIS-00773 ≤ MAX(SGN32)",
        "T: 0.1µm, R: 0.0001°", "Maximum permitted position change for fixed stop detection",
        "ISG online parameter docs (not in seeds)";
    MEAS_FS_POS_LAG_LIMIT = "P-AXIS-00774", "kenngr.measure.fixed_stop_detect.pos_lag_limit", Axis,
        Sgn32, di(-1), ri(S32_MIN + 1, S32_MAX - 1), "MIN(SGN32) < P-AXIS-00774 < MAX(SGN32)",
        "T: 0.1µm, R: 0.0001°",
        "Position lag limit for fixed stop detection, measuring travel to fixed stop",
        "seed 004 §8.2.2";
    MEAS_FS_MIN_TIME = "P-AXIS-00775", "kenngr.measure.fixed_stop_detect.min_time", Axis, Uns32,
        di(0), ri(0, U32 - 1), "0 < P-AXIS-00775 < MAX(UNS32)", "T: µs, R: µs",
        "Minimum time for fixed stop detection, measuring travel to fixed stop",
        "seed 004 §8.2.2";
    MEAS_FS_START_DISTANCE = "P-AXIS-00776", "kenngr.measure.fixed_stop_detect.start_distance",
        Axis, Sgn32, di(0), ri(S32_MIN + 1, S32_MAX), "MIN(SGN32) < P-AXIS-00776 < MAX(UNS32)",
        "T: 0.1µm, R: 0.0001°",
        "Minimum path to activate fixed stop detection, measuring travel to fixed stop",
        "seed 004 §8.2.2";
    MEAS_FS_START_DISTANCE_PER_MILLE = "P-AXIS-00777",
        "kenngr.measure.fixed_stop_detect.start_distance_per_mille", Axis, Sgn16, di(-1),
        ri(S16_MIN + 1, S16_MAX), "MIN(SGN16) < P-AXIS-00777 ≤ 1000", "T, R: 0.1%",
        "Minimum path to activate fixed stop detection, per mille of block length (> 1000: warning 110757 at start, error 51026 at measurement)",
        "seed 004 §8.2.2";
    MEAS_FS_MAX_DELTA_POSITION_WINDOW = "P-AXIS-00778",
        "kenngr.measure.fixed_stop_detect.max_delta_position_window", Axis, Sgn32, di(-1),
        ri(S32_MIN + 1, S32_MAX), "MIN(SGN32) < P-AXIS-00778 ≤ MAX(UNS32)", "T: 0.1µm, R: 0.0001°",
        "Maximum permitted position change during fixed stop detection, measuring travel to fixed stop",
        "seed 004 §8.2.2";
    MESSTYP = "P-CHAN-00057", "messtyp", Channel, Uns16, di(1), ri(1, 7),
        "1*, 2*, 3, 4, 5, 6, 7* (measurement types; * also with independent axes)", "----",
        "Predefine measurement type", "seed 004 §8.2.1";
    USE_DRIVE_CURR_LIMIT = "P-CHAN-00097", "use_drive_curr_limit", Channel, Boolean, di(0), BOOL,
        "0: currently valid deceleration rate, 1: parameterised feedhold deceleration depending on the slope (P-AXIS-00024 / P-AXIS-00053, P-AXIS-00081)",
        "----", "Valid deceleration ramp at FEEDHOLD", "seed 004 §8.2.1";
    MEAS_ERROR_NO_SIGNAL = "P-CHAN-00176", "meas_error_no_signal", Channel, Boolean, di(0), BOOL,
        "0: No output of an error message if no measurement signal is received (default), 1: Output of an error message if no measurement signal is received",
        "----", "Error reaction with measurement type 1", "seed 004 §8.2.1";
    MEAS_DECELERATION_MODE = "P-CHAN-00214", "meas_deceleration_mode", Channel, Uns16, di(0),
        ri(0, 1),
        "0: braked with feedhold deceleration (default), 1: braked with rapid traverse deceleration",
        "----", "Active delay with measurement signal", "seed 004 §8.2.1";
    MEAS_FIXED_STOP_NO_ERROR = "P-CHAN-00266", "meas_fixed_stop_no_error", Channel, Boolean, di(0),
        BOOL,
        "0: Output of an error message if the fixed stop is not detected (default), 1: No output of an error message if the fixed stop is not detected",
        "----", "Error reaction with measurement type 7", "seed 004 §8.2.1";
    MEAS_SOFT_LIMIT_MOVE_PATH = "P-CHAN-00268", "meas_soft_limit_move_path", Channel, Boolean,
        di(0), BOOL,
        "0: measurement motions with target outside software limit switches are not started, 1: started; stopped before the limit with error 50706",
        "----", "Automatic motion path limiting", "seed 000 §6.2";
    MEAS_USE_STD_DYNAMIC = "P-CHAN-00296", "meas_use_std_dynamic", Channel, Boolean, di(0), BOOL,
        "0: rapid traverse (G00) dynamics, 1: feed (G01) dynamics", "----",
        "Active dynamic for measurement run", "seed 004 §8.2.1";
    MEAS_PCS_VALUE_NO_PROBE_RADIUS = "P-CHAN-00311", "meas_pcs_value_no_probe_radius", Channel,
        Boolean, di(0), BOOL,
        "0: The ball radius of the probe is included in the PCS measured value (default), 1: The ball radius is not included",
        "----", "Include ball radius in calculation of PCS measured value",
        "ISG online parameter docs (not in seeds)";
    PCS_LIMITS_CONSIDER_MIRRORING = "P-CHAN-00434", "pcs_limits_consider_mirroring", Channel,
        Boolean, di(0), BOOL, "0/1", "----",
        "Consider active mirroring (G21-G23, G351) in the PCS limit display of P-CHAN-00489",
        "project assumption (mentioned in seed 001 §2.1; ISG name and definition not found)";
    SUPPRESS_WORKSPACE_MONITORING_MANUAL_MODE = "P-CHAN-00442",
        "suppress_workspace_monitoring_manual_mode", Channel, Uns16, di(0), ri(0, 2), "0, 1, 2",
        "----", "Suppression of workspace monitoring function in manual operation",
        "seed 000 §6.2";
    DISPLAY_PCS_LIMITS = "P-CHAN-00489", "display_pcs_limits", Channel, Boolean, di(0), BOOL,
        "0: The PCS display of motion range limits is disabled, 1: PCS motion range limits are calculated and supplied",
        "----", "Display motion range limits in PCS coordinate system", "seed 001 §4.2";
    RANGE_CHECK_PROG_SOFT_LIMITS = "P-CHAN-00498", "range_check_prog_soft_limits", Channel,
        Boolean, di(0), BOOL,
        "0: No limitation of the programmed values, 1: Limitation of the programmed values to the range of the software limit switches",
        "----", "Behaviour with programmed software limit switches", "seed 001 §4.2";
    MOVE_LIMIT_WARNING = "P-MANU-00014", "move_limit_warning", Manual, Boolean, di(0), BOOL,
        "0/1", "----", "Output a message at offset limit", "seed 001 §4.4, seed 000 §6.2";
}

/// Enumerated integer parameters whose valid values are not a contiguous range.
fn discrete_values(id: &str) -> Option<&'static [i64]> {
    match id {
        id::ANTR_TYP => Some(&[1, 2, 3, 4, 5, 6, 7, 8, 16, 32]),
        id::MASK_MESS_1 => Some(&[0x40, 0x80]),
        _ => None,
    }
}

/// Numeric encodings ISG also accepts for a few STRING parameters (P-AXIS-00018: 0x0001 …).
fn choice_alias(def: &ParamDef, text: &str) -> Option<&'static str> {
    if def.id != id::ACHS_TYP {
        return None;
    }
    match parse_int(text)? {
        1 => Some("ACHSTYP_TRANSLATOR"),
        2 => Some("ACHSTYP_ROTATOR"),
        4 => Some("ACHSTYP_SPINDEL"),
        _ => None,
    }
}

// ---------------------------------------------------------------------------------------------
// Lookup
// ---------------------------------------------------------------------------------------------

/// All parameter definitions, sorted by ID.
pub fn registry() -> &'static [ParamDef] {
    REGISTRY
}

/// Find a parameter by ID (case-insensitive, `P-AXIS-00177`) or by its exact ISG name path
/// (`kenngr.swe_neg`). An index written `[0]` is accepted for `[i]`
/// (`getriebe[0].dynamik.a_max`): fieldprobe models one gear stage / one hardware record.
pub fn find(key: &str) -> Option<&'static ParamDef> {
    let key = key.trim();
    if let Ok(i) = REGISTRY.binary_search_by(|d| d.id.cmp(key)) {
        return Some(&REGISTRY[i]);
    }
    if looks_like_id(key) {
        return REGISTRY.iter().find(|d| d.id.eq_ignore_ascii_case(key));
    }
    if key.contains("[0]") {
        let normalized = key.replace("[0]", "[i]");
        return REGISTRY.iter().find(|d| d.path == normalized);
    }
    REGISTRY.iter().find(|d| d.path == key)
}

/// The known parameter closest to `key` (edit distance over IDs, paths and path leaves), for
/// "did you mean" hints; `None` when nothing is reasonably close.
pub fn suggest(key: &str) -> Option<&'static ParamDef> {
    let key: String = key
        .trim()
        .chars()
        .take(96)
        .collect::<String>()
        .to_ascii_lowercase();
    if key.is_empty() {
        return None;
    }
    let key = key.replace("[0]", "[i]");
    let mut best: Option<(usize, &'static ParamDef)> = None;
    for def in REGISTRY {
        let mut d =
            edit_distance(&key, &def.id.to_ascii_lowercase()).min(edit_distance(&key, def.path));
        if let Some((_, rest)) = def.path.split_once('.') {
            d = d.min(edit_distance(&key, rest) + 1);
        }
        match best {
            Some((b, _)) if b <= d => {}
            _ => best = Some((d, def)),
        }
    }
    let limit = (key.chars().count() / 3).max(2);
    best.filter(|(d, _)| *d <= limit).map(|(_, def)| def)
}

/// The hint text for an unknown key: `'kenngr.swe_neg' (P-AXIS-00177)` for path-like keys,
/// `'P-AXIS-00177' (kenngr.swe_neg)` for ID-like keys.
pub(crate) fn suggestion_text(key: &str, def: &ParamDef) -> String {
    if looks_like_id(key) {
        format!("'{}' ({})", def.id, def.path)
    } else {
        format!("'{}' ({})", def.path, def.id)
    }
}

/// The error for an unknown key, with the closest known key as suggestion.
pub(crate) fn unknown_parameter(key: &str, origin: &Origin) -> ParamError {
    ParamError::UnknownParameter {
        origin: origin.clone(),
        key: key.to_string(),
        suggestion: suggest(key).map(|d| suggestion_text(key, d)),
    }
}

fn looks_like_id(key: &str) -> bool {
    key.trim()
        .get(..2)
        .is_some_and(|p| p.eq_ignore_ascii_case("P-"))
}

/// Levenshtein distance over characters (inputs are short keys).
pub(crate) fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for (i, ca) in a.chars().enumerate() {
        cur[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let subst = prev[j] + usize::from(ca != *cb);
            cur[j + 1] = subst.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[b.len()]
}

/// Strip one pair of surrounding `"…"` or `'…'`.
pub(crate) fn strip_quotes(s: &str) -> &str {
    for q in ['"', '\''] {
        if s.len() >= 2 && s.starts_with(q) && s.ends_with(q) {
            return &s[1..s.len() - 1];
        }
    }
    s
}

/// Parse a decimal or `0x` hexadecimal integer with optional sign. Values too large for `i128`
/// saturate (they are out of every range anyway).
pub(crate) fn parse_int(s: &str) -> Option<i128> {
    let (negative, body) = match s.as_bytes().first() {
        Some(b'-') => (true, &s[1..]),
        Some(b'+') => (false, &s[1..]),
        _ => (false, s),
    };
    let magnitude = if let Some(hex) = body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
        if hex.is_empty() || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
            return None;
        }
        i128::from_str_radix(hex, 16).unwrap_or(i128::MAX)
    } else {
        if body.is_empty() || !body.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        body.parse::<i128>().unwrap_or(i128::MAX)
    };
    Some(if negative { -magnitude } else { magnitude })
}

// ---------------------------------------------------------------------------------------------
// ParamSet
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Clone, PartialEq, Eq)]
struct Entry {
    def: &'static ParamDef,
    value: ParamValue,
    origin: Origin,
}

/// The values of one parameter list (one axis, the channel or manual mode): the explicitly set
/// values keyed by ID, each with its origin; everything else reads as the registry default.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParamSet {
    scope: Scope,
    label: Option<String>,
    values: BTreeMap<&'static str, Entry>,
}

impl ParamSet {
    /// An empty set (all parameters at their defaults).
    pub fn new(scope: Scope) -> Self {
        ParamSet {
            scope,
            label: None,
            values: BTreeMap::new(),
        }
    }

    /// The list this set holds.
    pub fn scope(&self) -> Scope {
        self.scope
    }

    /// Set a label used in cross-check messages, e.g. `axis X`.
    pub fn set_label(&mut self, label: impl Into<String>) {
        self.label = Some(label.into());
    }

    /// The label, if any.
    pub fn label(&self) -> Option<&str> {
        self.label.as_deref()
    }

    fn lookup(&self, id: &str) -> Option<(&'static ParamDef, Option<&ParamValue>)> {
        let def = find(id)?;
        Some((def, self.values.get(def.id).map(|e| &e.value)))
    }

    /// Integer value of a parameter: the set value or the registry default. STRING parameters
    /// read as 0; an unknown ID reads as 0 (and trips a debug assertion).
    pub fn int(&self, id: &str) -> i64 {
        let found = self.lookup(id);
        debug_assert!(found.is_some(), "unknown parameter '{id}'");
        match found {
            Some((_, Some(ParamValue::Int(v)))) => *v,
            Some((_, Some(ParamValue::Text(_)))) => 0,
            Some((def, None)) => match def.default {
                DefaultValue::Int(v) => v,
                DefaultValue::Text(_) => 0,
            },
            None => 0,
        }
    }

    /// Text value of a parameter: the set value or the default (`""` for integer parameters and
    /// unknown IDs, the latter tripping a debug assertion).
    pub fn text(&self, id: &str) -> &str {
        let found = self.lookup(id);
        debug_assert!(found.is_some(), "unknown parameter '{id}'");
        match found {
            Some((_, Some(ParamValue::Text(s)))) => s,
            Some((def, None)) => match def.default {
                DefaultValue::Text(s) => s,
                DefaultValue::Int(_) => "",
            },
            _ => "",
        }
    }

    /// Whether the parameter was set explicitly (by ID or path).
    pub fn is_set(&self, id: &str) -> bool {
        find(id).is_some_and(|d| self.values.contains_key(d.id))
    }

    /// The explicitly set value, if any.
    pub fn get(&self, id: &str) -> Option<&ParamValue> {
        self.lookup(id).and_then(|(_, v)| v)
    }

    /// Where the explicitly set value came from.
    pub fn origin_of(&self, id: &str) -> Option<&Origin> {
        find(id)
            .and_then(|d| self.values.get(d.id))
            .map(|e| &e.origin)
    }

    /// Set a parameter from its text form. `key` is an ID or a name path; the raw text is parsed
    /// per type and range-checked ([`ParamDef::parse_value`]). A parameter of another list is an
    /// error naming the right section.
    pub fn set(
        &mut self,
        key: &str,
        raw: &str,
        origin: &Origin,
    ) -> Result<&'static ParamDef, ParamError> {
        let def = find(key).ok_or_else(|| unknown_parameter(key, origin))?;
        self.check_scope(def, origin)?;
        let value = def.parse_value(raw, origin)?;
        self.values.insert(
            def.id,
            Entry {
                def,
                value,
                origin: origin.clone(),
            },
        );
        Ok(def)
    }

    /// Set an integer parameter through the API (range-checked, origin `<api>`).
    pub fn set_int(&mut self, id: &str, v: i64) -> Result<(), ParamError> {
        let origin = Origin::api();
        let def = find(id).ok_or_else(|| unknown_parameter(id, &origin))?;
        self.check_scope(def, &origin)?;
        if def.is_text() {
            return Err(ParamError::InvalidValue {
                origin,
                def,
                value: v.to_string(),
            });
        }
        if !def.accepts_int(v) {
            return Err(ParamError::OutOfRange {
                origin,
                def,
                value: v.to_string(),
            });
        }
        self.values.insert(
            def.id,
            Entry {
                def,
                value: ParamValue::Int(v),
                origin,
            },
        );
        Ok(())
    }

    fn check_scope(&self, def: &'static ParamDef, origin: &Origin) -> Result<(), ParamError> {
        if def.scope == self.scope {
            Ok(())
        } else {
            Err(ParamError::WrongScope {
                origin: origin.clone(),
                def,
                found: self.scope,
            })
        }
    }

    /// The explicitly set values, in ID order.
    pub fn iter_set(&self) -> impl Iterator<Item = (&'static ParamDef, &ParamValue)> {
        self.values.values().map(|e| (e.def, &e.value))
    }

    /// Check the ranges that refer to other parameters: P-AXIS-00177 < P-AXIS-00178 (FCT-A2
    /// §4.3), P-AXIS-00177 ≤ P-AXIS-00492/00493 ≤ P-AXIS-00178 when set (≠ 0), accelerations
    /// ≤ P-AXIS-00008 (a_emergency ≤ 2 × P-AXIS-00008), vb_messen ≤ P-AXIS-00212 (FCT-C4
    /// §8.2.2). The error's origin is the last assignment (in `origin.file`) of a parameter
    /// involved, else `origin`.
    pub fn check_cross(&self, origin: &Origin) -> Result<(), ParamError> {
        if self.scope != Scope::Axis {
            return Ok(());
        }
        let neg = self.int(id::SWE_NEG);
        let pos = self.int(id::SWE_POS);
        if neg >= pos {
            return Err(self.cross_error(
                origin,
                id::SWE_NEG,
                &format!("< {}", self.show(id::SWE_POS)),
                &[id::SWE_POS],
            ));
        }
        // P-AXIS-00127 modulou < P-AXIS-00126 moduloo (ISG axis parameter docs).
        if self.int(id::MODULOU) >= self.int(id::MODULOO) {
            return Err(self.cross_error(
                origin,
                id::MODULOU,
                &format!("< {}", self.show(id::MODULOO)),
                &[id::MODULOO],
            ));
        }
        for limit in [id::ACS_LIMIT_NEG, id::ACS_LIMIT_POS] {
            let v = self.int(limit);
            if v != 0 && v < neg {
                return Err(self.cross_error(
                    origin,
                    limit,
                    &format!("≥ {}", self.show(id::SWE_NEG)),
                    &[id::SWE_NEG],
                ));
            }
            if v != 0 && v > pos {
                return Err(self.cross_error(
                    origin,
                    limit,
                    &format!("≤ {}", self.show(id::SWE_POS)),
                    &[id::SWE_POS],
                ));
            }
        }
        let a_max = self.int(id::A_MAX);
        for acc in [
            id::A_BESCHL,
            id::A_BREMS,
            id::A_GRENZ,
            id::A_GRENZ_STUFE_1,
            id::A_GRENZ_STUFE_2,
            id::A_STUFE_1,
            id::A_STUFE_2,
            id::LSLOPE_A_FEEDH,
            id::SLOPE_A_FEEDH,
            id::D_GRENZ_STUFE_1,
            id::D_GRENZ_STUFE_2,
            id::D_STUFE_1,
            id::D_STUFE_2,
        ] {
            if self.int(acc) > a_max {
                return Err(self.cross_error(
                    origin,
                    acc,
                    &format!("≤ {}", self.show(id::A_MAX)),
                    &[id::A_MAX],
                ));
            }
        }
        if self.int(id::A_EMERGENCY) > 2 * a_max {
            let req = format!("≤ 2 × {} = {}", self.show(id::A_MAX), 2 * a_max);
            return Err(self.cross_error(origin, id::A_EMERGENCY, &req, &[id::A_MAX]));
        }
        if self.int(id::VB_MESSEN) > self.int(id::VB_MAX) {
            return Err(self.cross_error(
                origin,
                id::VB_MESSEN,
                &format!("≤ {}", self.show(id::VB_MAX)),
                &[id::VB_MAX],
            ));
        }
        Ok(())
    }

    fn show(&self, id: &str) -> String {
        match find(id) {
            Some(def) => format!("{} {} = {}", def.id, def.path, self.int(id)),
            None => id.to_string(),
        }
    }

    fn cross_error(
        &self,
        origin: &Origin,
        subject: &str,
        requirement: &str,
        others: &[&str],
    ) -> ParamError {
        let origins: Vec<&Origin> = std::iter::once(subject)
            .chain(others.iter().copied())
            .filter_map(|id| self.values.get(id).map(|e| &e.origin))
            .collect();
        let same_file = origins
            .iter()
            .filter(|o| o.file == origin.file)
            .max_by_key(|o| o.line);
        let chosen = same_file
            .or_else(|| origins.iter().max_by_key(|o| o.line))
            .map(|o| (*o).clone())
            .unwrap_or_else(|| origin.clone());
        let def = find(subject).unwrap_or(&REGISTRY[0]);
        ParamError::CrossCheck {
            origin: chosen,
            context: self
                .label
                .as_ref()
                .map(|l| format!(" ({l})"))
                .unwrap_or_default(),
            def,
            value: self.int(subject),
            requirement: requirement.to_string(),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Documentation table
// ---------------------------------------------------------------------------------------------

/// The Markdown text of `docs/parameters.md`: one table row per parameter.
pub fn parameters_markdown() -> String {
    let mut out = String::new();
    out.push_str("# Parameters\n\n");
    out.push_str(
        "Generated from `src/params/registry.rs` by `cargo test --test it params::` \
         (`FIELDPROBE_BLESS=1` rewrites it). Do not edit by hand.\n\n",
    );
    out.push_str(
        "Every P-AXIS-\\*, P-CHAN-\\* and P-MANU-\\* parameter named in the seeds (plus \
         P-AXIS-00008, the bound of the acceleration ranges). *Range* is the source's wording; \
         *accepted* is what the loader checks on its own. Ranges that name another parameter are \
         checked after loading (cross checks). Where the source's range excludes the source's own \
         default (a default that selects a fallback, e.g. `0 < min_time` with default 0), the \
         accepted range includes the default. P-AXIS-00772/00777 accept values above 1000: the \
         seed reports them at start (warning 110757) and at the measurement (error 51026). \
         Source *ISG online parameter docs (not in seeds)*: the seeds only mention the parameter; \
         *project assumption*: no definition was found.\n\n",
    );
    out.push_str(
        "| ID | path | type | default | range | accepted | dimension | title | source |\n",
    );
    out.push_str("|---|---|---|---|---|---|---|---|---|\n");
    for d in REGISTRY {
        let default = match d.default {
            DefaultValue::Int(v) => v.to_string(),
            DefaultValue::Text("") => "(blank)".to_string(),
            DefaultValue::Text(s) => s.to_string(),
        };
        let accepted = match d.range {
            Range::Int { min, max } => match discrete_values(d.id) {
                Some(vals) => vals
                    .iter()
                    .map(|v| v.to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
                None => format!("{min} … {max}"),
            },
            Range::Choice(words) if d.default == DefaultValue::Text("") => {
                format!("{} or blank", words.join(", "))
            }
            Range::Choice(words) => words.join(", "),
            Range::AnyText => "any text".to_string(),
        };
        out.push_str(&format!(
            "| {} | `{}` | {} | {} | {} | {} | {} | {} | {} |\n",
            d.id,
            d.path,
            d.ty,
            md(&default),
            md(d.range_text),
            md(&accepted),
            md(d.dimension),
            md(d.title),
            md(d.source),
        ));
    }
    out
}

fn md(s: &str) -> String {
    s.replace('\\', "\\\\")
        .replace('|', "\\|")
        .replace('*', "\\*")
        .replace('_', "\\_")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registry_sorted_and_unique() {
        for w in REGISTRY.windows(2) {
            assert!(w[0].id < w[1].id, "{} !< {}", w[0].id, w[1].id);
        }
        let mut paths: Vec<_> = REGISTRY.iter().map(|d| d.path).collect();
        paths.sort_unstable();
        paths.dedup();
        assert_eq!(paths.len(), REGISTRY.len());
    }

    #[test]
    fn scope_matches_id_prefix() {
        for d in REGISTRY {
            assert!(d.id.starts_with(d.scope.id_prefix()), "{}", d.id);
        }
    }

    #[test]
    fn edit_distance_basics() {
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("swe_nge", "swe_neg"), 2);
    }

    #[test]
    fn parse_int_forms() {
        assert_eq!(parse_int("10"), Some(10));
        assert_eq!(parse_int("-0x10"), Some(-16));
        assert_eq!(parse_int("+7"), Some(7));
        assert_eq!(parse_int("0x"), None);
        assert_eq!(parse_int("1e3"), None);
        assert_eq!(parse_int("-"), None);
        assert_eq!(
            parse_int("99999999999999999999999999999999999999999"),
            Some(i128::MAX)
        );
    }

    #[test]
    fn quotes() {
        assert_eq!(strip_quotes("\"PLC\""), "PLC");
        assert_eq!(strip_quotes("'x'"), "x");
        assert_eq!(strip_quotes("\""), "\"");
    }

    #[test]
    fn achs_typ_numeric_alias() {
        let mut s = ParamSet::new(Scope::Axis);
        s.set("kenngr.achs_typ", "0x0002", &Origin::api()).unwrap();
        assert_eq!(s.text(id::ACHS_TYP), "ACHSTYP_ROTATOR");
    }

    #[test]
    fn discrete_drive_type() {
        let mut s = ParamSet::new(Scope::Axis);
        assert!(s.set_int(id::ANTR_TYP, 8).is_ok());
        assert!(s.set_int(id::ANTR_TYP, 9).is_err());
    }
}
