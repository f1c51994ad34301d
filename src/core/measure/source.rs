//! Which probing signal, input and edge an axis measures with, from its parameter list: the
//! parameters of CNC Build V2.11.2019.15 (P-AXIS-00516 / 00517 / 00518) when they are given,
//! else the old ones they replace (FCT-C4 §8.2.2 remarks, §8.2.4). This is the one place that
//! reads them: the channel's run configuration, `check`, the drive commissioning checks and the
//! machine's input check all go through [`ProbeSettings::from_params`].
//!
//! | new | given when | else (old, in this order) |
//! |---|---|---|
//! | P-AXIS-00516 `kenngr.measure.signal` | not blank | P-AXIS-00330 = 1 → `FIXED_STOP`, P-AXIS-00257 = 1 → `PLC`, P-AXIS-00115 = 1 → `PLC`, P-AXIS-00116 = 1 → `DRIVE`, P-AXIS-00269 = 1 → `DRIVE`; none → `DRIVE_TYPE_DEFAULT` |
//! | P-AXIS-00517 `kenngr.measure.input` | not 0 | P-AXIS-00430 (not 0), P-AXIS-00295 (not 0); none → 1 |
//! | P-AXIS-00518 `kenngr.measure.edge` | not blank | P-AXIS-00113 (0 → `POS`, 1 → `NEG`) |
//!
//! A parameter the machine sets that has no effect (an old one beside its replacement, or
//! P-AXIS-00117, whose NC-kernel hardware interface fieldprobe does not have) is reported as
//! [`Unused`], warning [`crate::messages::ids::MEAS_PARAM_UNUSED`] (docs/interpretations.md
//! M29). Two old source parameters that select different sources are refused: "All other
//! measurement signal sources (e.g. P-AXIS-00116) must be deselected" (P-AXIS-00330 remarks).

use super::SignalSource;
use crate::drive::ProbeEdge;
use crate::messages::{ids, CncMessage};
use crate::params::ParamSet;

/// The old source parameters (FCT-C4 §8.2.4, replaced by P-AXIS-00516) and what value 1 of
/// each selects; `None`: no source of fieldprobe's (P-AXIS-00117, the NC kernel's hardware
/// interface). The order is the order of the table in the module documentation.
const OLD_SOURCES: [(&str, Option<SignalSource>); 6] = [
    // "This parameter enables the measurement signal source 'Fixed stop'" (§8.2.4); §7.3
    // "P-AXIS-00516 (Previous P-AXIS-00330) … FIXED_STOP".
    ("P-AXIS-00330", Some(SignalSource::FixedStop)),
    // "the probing signal is read from the HLI via the control unit PLC parameters … The
    // probing value is the actual value at the moment of the occurrence of the probing signal"
    // (§8.2.4) — the PLC source of §7.1.
    ("P-AXIS-00257", Some(SignalSource::Plc)),
    // "one bit in the axis-specific control bit mask is treated as the measurement signal"
    // (§8.2.4): the axis control bits come from the PLC interface (§7.1 "See also [Axis
    // control commands]").
    ("P-AXIS-00115", Some(SignalSource::Plc)),
    // §6.1 "P-AXIS-00516 (old: P-AXIS-00116) Measuring by drive: kenngr.measure.signal DRIVE".
    ("P-AXIS-00116", Some(SignalSource::Drive)),
    // `kenngr.meas_signal_drive`: the measurement signal from the drive.
    ("P-AXIS-00269", Some(SignalSource::Drive)),
    // "selects the use of the NC kernel hardware interface" (§8.2.4): none here.
    ("P-AXIS-00117", None),
];

/// Where a resolved value came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// The parameter of that ID (new or old).
    Param(&'static str),
    /// Neither the new nor an old parameter: the default.
    Default,
}

impl Origin {
    /// The parameter's ID, or `new` (the new parameter's) for [`Origin::Default`].
    pub fn id_or(self, new: &'static str) -> &'static str {
        match self {
            Origin::Param(id) => id,
            Origin::Default => new,
        }
    }

    /// `P-AXIS-00330 kenngr.meas_signal_fixed_stop` / `default`, for messages.
    pub fn words(self) -> String {
        match self {
            Origin::Param(id) => with_path(id),
            Origin::Default => "no parameter (default)".into(),
        }
    }
}

/// A parameter the machine sets that has no effect, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unused {
    /// Its ID.
    pub id: &'static str,
    /// Why, in words (names the parameter that takes its place).
    pub why: String,
}

/// The probing signal settings of one axis (FCT-C4 §8.2.2 P-AXIS-00516 / 00517 / 00518 with
/// their backward-compatible fallbacks).
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeSettings {
    /// The source of the probing signal.
    pub signal: SignalSource,
    /// Where [`signal`](Self::signal) came from.
    pub signal_origin: Origin,
    /// The probing input (1 …).
    pub input: u8,
    /// Where [`input`](Self::input) came from.
    pub input_origin: Origin,
    /// The latching edge.
    pub edge: ProbeEdge,
    /// Where [`edge`](Self::edge) came from.
    pub edge_origin: Origin,
    /// Parameters set without effect.
    pub unused: Vec<Unused>,
}

/// `P-AXIS-00330 kenngr.meas_signal_fixed_stop`.
fn with_path(id: &str) -> String {
    match crate::params::find(id) {
        Some(d) => format!("{id} {}", d.path),
        None => id.to_string(),
    }
}

/// The value of `id` as the machine wrote it, for messages.
fn value_words(p: &ParamSet, id: &str) -> String {
    match crate::params::find(id) {
        Some(d) if d.is_text() => format!("'{}'", p.text(id)),
        _ => p.int(id).to_string(),
    }
}

impl ProbeSettings {
    /// Resolve the settings of the axis parameter list `p` (module documentation).
    ///
    /// # Errors
    /// Two old source parameters select different sources (P-AXIS-00516 not given): the text
    /// names both and the way out.
    pub fn from_params(p: &ParamSet) -> Result<Self, String> {
        let mut unused = Vec::new();
        let superseded = |unused: &mut Vec<Unused>, old: &'static str, new: &str| {
            if p.is_set(old) {
                unused.push(Unused {
                    id: old,
                    why: format!(
                        "{} = {} has no effect: {} = {} is given and replaces it (seed 004 §8.2.2)",
                        with_path(old),
                        value_words(p, old),
                        with_path(new),
                        value_words(p, new)
                    ),
                });
            }
        };

        // P-AXIS-00516 — "If the parameter P-AXIS-00516 is not defined, the measurement method
        // resulting from previous parameters is used" (default: a blank string).
        let new_signal = p.text("P-AXIS-00516").trim();
        let (signal, signal_origin) = if !new_signal.is_empty() {
            let s = SignalSource::from_text(new_signal).ok_or_else(|| {
                format!(
                    "{} = '{new_signal}': allowed are DRIVE_TYPE_DEFAULT PLC FIXED_STOP DRIVE \
                     PLC_EXT_LATCH_CONTROL PLC_FIRST_EVENT PLC_TIMESTAMP EXT_PROBE_WITH_DRIVE \
                     (seed 004 §8.2.2)",
                    with_path("P-AXIS-00516")
                )
            })?;
            for (old, _) in OLD_SOURCES {
                superseded(&mut unused, old, "P-AXIS-00516");
            }
            (s, Origin::Param("P-AXIS-00516"))
        } else {
            let mut chosen: Option<(SignalSource, &'static str)> = None;
            for (old, source) in OLD_SOURCES {
                if p.int(old) == 0 {
                    continue;
                }
                let Some(source) = source else {
                    unused.push(Unused {
                        id: old,
                        why: format!(
                            "{} = 1 has no effect: fieldprobe has no NC-kernel hardware probe \
                             interface; the axis measures with {} (P-AXIS-00516 not given, \
                             seed 004 §8.2.4)",
                            with_path(old),
                            SignalSource::DriveTypeDefault.name()
                        ),
                    });
                    continue;
                };
                match chosen {
                    Some((first, first_id)) if first != source => {
                        return Err(format!(
                            "{} = 1 selects {} and {} = 1 selects {}: only one measurement \
                             signal source may be selected (\"All other measurement signal \
                             sources … must be deselected\", seed 004 §8.2.4 P-AXIS-00330); set \
                             one of them to 0, or give {} (one of DRIVE_TYPE_DEFAULT PLC \
                             FIXED_STOP DRIVE PLC_EXT_LATCH_CONTROL PLC_FIRST_EVENT PLC_TIMESTAMP \
                             EXT_PROBE_WITH_DRIVE), which replaces them",
                            with_path(first_id),
                            first.name(),
                            with_path(old),
                            source.name(),
                            with_path("P-AXIS-00516")
                        ));
                    }
                    Some(_) => {}
                    None => chosen = Some((source, old)),
                }
            }
            match chosen {
                Some((s, id)) => (s, Origin::Param(id)),
                None => (SignalSource::DriveTypeDefault, Origin::Default),
            }
        };

        // P-AXIS-00517 — "If the parameter P-AXIS-00517 is not specified, the setting in
        // P-AXIS-00430 is used"; §6.4 names P-AXIS-00295 as its older predecessor on
        // CANopen / EtherCAT drives. Default 0 = not specified.
        let mut input = None;
        for id in ["P-AXIS-00517", "P-AXIS-00430", "P-AXIS-00295"] {
            let v = p.int(id);
            match input {
                None if v != 0 => {
                    let n = u8::try_from(v).map_err(|_| {
                        format!("{} = {v}: allowed 0 … 255 (seed 004 §8.2.2)", with_path(id))
                    })?;
                    input = Some((n, id));
                }
                Some((_, given)) => superseded(&mut unused, id, given),
                None => {}
            }
        }
        let (input, input_origin) = match input {
            Some((n, id)) => (n, Origin::Param(id)),
            None => (1, Origin::Default),
        };

        // P-AXIS-00518 — "If the parameter P-AXIS-00518 is not specified, the setting in
        // P-AXIS-00113 is output" (0: positive edge, 1: negative edge; default 0).
        let new_edge = p.text("P-AXIS-00518").trim();
        let (edge, edge_origin) = if !new_edge.is_empty() {
            let e = super::edge_from_text(new_edge).ok_or_else(|| {
                format!(
                    "{} = '{new_edge}': allowed POS / NEG (seed 004 §8.2.2)",
                    with_path("P-AXIS-00518")
                )
            })?;
            superseded(&mut unused, "P-AXIS-00113", "P-AXIS-00518");
            (e, Origin::Param("P-AXIS-00518"))
        } else {
            let e = if p.int("P-AXIS-00113") != 0 {
                ProbeEdge::Negative
            } else {
                ProbeEdge::Positive
            };
            let origin = if p.is_set("P-AXIS-00113") {
                Origin::Param("P-AXIS-00113")
            } else {
                Origin::Default
            };
            (e, origin)
        };

        Ok(ProbeSettings {
            signal,
            signal_origin,
            input,
            input_origin,
            edge,
            edge_origin,
            unused,
        })
    }

    /// The [`Unused`] parameters as warnings for axis `axis`.
    pub fn warnings(&self, axis: &str) -> Vec<CncMessage> {
        self.unused
            .iter()
            .map(|u| {
                CncMessage::warning(ids::MEAS_PARAM_UNUSED, format!("axis {axis}: {}", u.why))
                    .on_axis(axis)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{Origin as At, Scope};

    fn params(sets: &[(&str, &str)]) -> ParamSet {
        let mut p = ParamSet::new(Scope::Axis);
        for (k, v) in sets {
            p.set(k, v, &At::new("test", 0)).unwrap();
        }
        p
    }

    #[test]
    fn nothing_given_is_the_drive_type_default_input_1_positive_edge() {
        let s = ProbeSettings::from_params(&params(&[])).unwrap();
        assert_eq!(s.signal, SignalSource::DriveTypeDefault);
        assert_eq!((s.input, s.edge), (1, ProbeEdge::Positive));
        assert!(s.unused.is_empty());
    }

    #[test]
    fn old_parameters_apply_when_the_new_ones_are_blank() {
        let s = ProbeSettings::from_params(&params(&[
            ("P-AXIS-00330", "1"),
            ("P-AXIS-00430", "2"),
            ("P-AXIS-00113", "1"),
        ]))
        .unwrap();
        assert_eq!(s.signal, SignalSource::FixedStop);
        assert_eq!(s.signal_origin, Origin::Param("P-AXIS-00330"));
        assert_eq!((s.input, s.edge), (2, ProbeEdge::Negative));
        assert!(s.unused.is_empty(), "{:?}", s.unused);
        let s = ProbeSettings::from_params(&params(&[("P-AXIS-00257", "1")])).unwrap();
        assert_eq!(s.signal, SignalSource::Plc);
        // A blank new parameter is "not defined" too.
        let s = ProbeSettings::from_params(&params(&[
            ("P-AXIS-00516", ""),
            ("P-AXIS-00518", ""),
            ("P-AXIS-00257", "1"),
            ("P-AXIS-00113", "1"),
        ]))
        .unwrap();
        assert_eq!((s.signal, s.edge), (SignalSource::Plc, ProbeEdge::Negative));
    }

    #[test]
    fn new_parameters_win_and_the_old_ones_set_beside_them_are_named() {
        let s = ProbeSettings::from_params(&params(&[
            ("P-AXIS-00516", "DRIVE"),
            ("P-AXIS-00330", "1"),
            ("P-AXIS-00517", "1"),
            ("P-AXIS-00430", "2"),
            ("P-AXIS-00518", "POS"),
            ("P-AXIS-00113", "1"),
        ]))
        .unwrap();
        assert_eq!(s.signal, SignalSource::Drive);
        assert_eq!((s.input, s.edge), (1, ProbeEdge::Positive));
        let ids: Vec<_> = s.unused.iter().map(|u| u.id).collect();
        assert_eq!(ids, ["P-AXIS-00330", "P-AXIS-00430", "P-AXIS-00113"]);
        assert!(s.unused[0].why.contains("P-AXIS-00516"), "{:?}", s.unused);
    }

    #[test]
    fn two_old_sources_that_disagree_are_refused_naming_both() {
        let e =
            ProbeSettings::from_params(&params(&[("P-AXIS-00330", "1"), ("P-AXIS-00257", "1")]))
                .unwrap_err();
        assert!(
            e.contains("P-AXIS-00330") && e.contains("P-AXIS-00257"),
            "{e}"
        );
        // Two that agree are one source.
        let s =
            ProbeSettings::from_params(&params(&[("P-AXIS-00116", "1"), ("P-AXIS-00269", "1")]))
                .unwrap();
        assert_eq!(s.signal, SignalSource::Drive);
    }

    #[test]
    fn p_axis_00117_has_no_source_here_and_is_named() {
        let s = ProbeSettings::from_params(&params(&[("P-AXIS-00117", "1")])).unwrap();
        assert_eq!(s.signal, SignalSource::DriveTypeDefault);
        assert_eq!(s.unused.len(), 1);
        assert_eq!(s.unused[0].id, "P-AXIS-00117");
    }
}
