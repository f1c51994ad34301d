//! A measuring motion evaluated cycle by cycle without the NC channel: for a drive layer that
//! runs its own interpolator and wants the CNC's rules for the probing signal (FCT-C4
//! Measurement §1–§5).
//!
//! The caller plans a straight measuring motion from `start` to `target` (ACS, one entry per
//! axis), moves the axes itself and hands [`MeasurementRun::cycle`] the latch events its drives
//! reported in that cycle. The run says when the probing signal is complete and the motion
//! must brake ([`RunStep::Brake`]); at standstill [`MeasurementRun::finish`] applies the
//! measurement type's rule for a missing signal and returns the [`MeasurementOutcome`]
//! (latched ACS positions, `V.A.MERF`), which [`super::results::compute`] turns into
//! `V.A.MESS`, `V.A.MEAS.ACS.VALUE`, `V.A.MEAS.PCS.VALUE` and `V.A.MOFFS`. The NC channel
//! applies the same rules ([`contact_path_position`], [`latched_before_target`],
//! [`missing_signal_error`]) to its G100 blocks.
//!
//! | rule | FCT-C4 |
//! |---|---|
//! | every measurement axis (P-AXIS-00118) the motion moves must latch; programmed axes that do not move are armed and may latch | §1, §4 |
//! | the signal is complete when every moved axis latched: brake (type 3: go on to the target) | §3 table |
//! | `V.A.MERF`: the contact lies on the path before the programmed target | §8 |
//! | no signal: type 2 error; type 1 error with P-CHAN-00176 = 1; a path cut at a software limit switch (P-CHAN-00268) error 50706 | §3, §8.2.1 |
//!
//! Types 1–4 (G100 with a latch in the drive or in external hardware) run here. Type 5 (G210),
//! type 6 (G310, SERCOS) and type 7 (fixed stop, [`super::fixed_stop::FixedStopDetector`]) need
//! the channel's interpolator and are refused by [`MeasurementRun::new`].
//!
//! Sans-IO: no clock, no allocation per cycle.

use super::{ChannelMeasConfig, MeasType, MeasurementOutcome};
use crate::messages::{ids, CncMessage};
use crate::units::Nanos;

/// A contact closer to the programmed target than this (mm) counts as at the target (`V.A.MERF`
/// 0): far below the 0.1 µm resolution of the drives' positions.
pub const CONTACT_AT_TARGET: f64 = 1e-6;

/// An axis moves in the motion when start and target differ by more than this (mm / °).
const MOVED: f64 = 1e-9;

/// One latch event a drive (or external latch hardware) reported.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Latch {
    /// Axis index (position in the run's per-axis slices).
    pub axis: usize,
    /// Latched ACS position (mm / °), e.g. `Scaling::to_units` of CiA 402 0x60BA.
    pub position: f64,
}

/// What the motion must do after a cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunStep {
    /// Go on towards the target.
    Continue,
    /// The probing signal became complete in this cycle: brake now (FCT-C4 §2.1, "measurement
    /// signal active"). Returned once.
    Brake,
}

/// One axis of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
struct RunAxis {
    /// Takes part: armed, its latch is recorded.
    involved: bool,
    /// Must latch for the signal to be complete (a moved measurement axis).
    required: bool,
    latched: Option<(f64, Nanos)>,
}

/// A measuring motion (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementRun {
    mtype: MeasType,
    cfg: ChannelMeasConfig,
    axes: Vec<RunAxis>,
    origin: Vec<f64>,
    dir: Vec<f64>,
    target_len: f64,
    signalled: bool,
    limited_at_sls: bool,
}

impl MeasurementRun {
    /// A run of type `mtype` from `start` to `target` (ACS). `programmed`: the axes named in the
    /// measuring block; `measurement_axis`: P-AXIS-00118 `kenngr.messachse` per axis; `cfg`:
    /// the channel's measurement parameters (P-CHAN-00176 …).
    ///
    /// # Errors
    /// Slices of different lengths or non-finite positions; a type this run does not evaluate
    /// (5, 6, 7); type 2 with other than one moved axis; a moved axis that is not a measurement
    /// axis; no moved measurement axis (error 900040, `ids::MEAS_CONFIG`).
    pub fn new(
        mtype: MeasType,
        start: &[f64],
        target: &[f64],
        programmed: &[bool],
        measurement_axis: &[bool],
        cfg: &ChannelMeasConfig,
    ) -> Result<Self, CncMessage> {
        let config = |text: String| CncMessage::error(ids::MEAS_CONFIG, text);
        let n = start.len();
        if target.len() != n || programmed.len() != n || measurement_axis.len() != n {
            return Err(config(format!(
                "measuring motion: {n} start coordinates, {} target coordinates, {} programmed \
                 flags, {} measurement-axis flags; one per axis each",
                target.len(),
                programmed.len(),
                measurement_axis.len()
            )));
        }
        if let Some(i) = (0..n).find(|&i| !(start[i].is_finite() && target[i].is_finite())) {
            return Err(config(format!(
                "measuring motion: axis {i} has a start or target that is not finite"
            )));
        }
        if matches!(mtype, MeasType::Type5 | MeasType::Type6 | MeasType::Type7) {
            return Err(config(format!(
                "measurement type {} needs the NC channel's interpolator (G210 / G310 / fixed \
                 stop); a measuring motion of its own evaluates types 1–4",
                mtype.number()
            )));
        }
        let moved: Vec<bool> = (0..n)
            .map(|i| (target[i] - start[i]).abs() > MOVED)
            .collect();
        let moved_count = moved.iter().filter(|m| **m).count();
        if mtype == MeasType::Type2 && moved_count != 1 {
            return Err(config(format!(
                "measurement type 2 moves exactly one axis; this motion moves {moved_count}"
            )));
        }
        if let Some(i) = (0..n).find(|&i| moved[i] && !measurement_axis[i]) {
            return Err(config(format!(
                "axis {i} moves but is not a measurement axis (P-AXIS-00118 kenngr.messachse = 0)"
            )));
        }
        if moved_count == 0 {
            return Err(config(
                "measuring block without a moved measurement axis".into(),
            ));
        }
        let len = (0..n)
            .map(|i| (target[i] - start[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        Ok(MeasurementRun {
            mtype,
            cfg: *cfg,
            axes: (0..n)
                .map(|i| RunAxis {
                    involved: measurement_axis[i] && (moved[i] || programmed[i]),
                    required: moved[i],
                    latched: None,
                })
                .collect(),
            origin: start.to_vec(),
            dir: (0..n).map(|i| (target[i] - start[i]) / len).collect(),
            target_len: len,
            signalled: false,
            limited_at_sls: false,
        })
    }

    /// The measurement type.
    pub fn mtype(&self) -> MeasType {
        self.mtype
    }

    /// Length of the motion up to the programmed target (mm).
    pub fn target_len(&self) -> f64 {
        self.target_len
    }

    /// The caller cut the motion short at a software limit switch or control-area boundary
    /// (P-CHAN-00268): a run that ends there without signal is error 50706.
    pub fn set_limited_at_sls(&mut self, limited: bool) {
        self.limited_at_sls = limited;
    }

    /// One cycle at `now` with the latches reported in it. The first latch of each involved
    /// axis counts (first event); latches of other axes and later ones are ignored.
    pub fn cycle(&mut self, now: Nanos, latches: &[Latch]) -> RunStep {
        for l in latches {
            if let Some(a) = self.axes.get_mut(l.axis) {
                if a.involved && a.latched.is_none() && l.position.is_finite() {
                    a.latched = Some((l.position, now));
                }
            }
        }
        if !self.signalled && self.complete() {
            self.signalled = true;
            if self.mtype != MeasType::Type3 {
                return RunStep::Brake;
            }
        }
        RunStep::Continue
    }

    /// Every moved axis latched: the probing signal is complete.
    pub fn complete(&self) -> bool {
        self.axes
            .iter()
            .filter(|a| a.required)
            .all(|a| a.latched.is_some())
            && self.axes.iter().any(|a| a.latched.is_some())
    }

    /// The latch of axis `axis` so far: (ACS position, when).
    pub fn latched(&self, axis: usize) -> Option<(f64, Nanos)> {
        self.axes.get(axis).and_then(|a| a.latched)
    }

    /// The motion is at standstill: `target_reached` when it ended at the programmed target.
    /// Applies the type's rule for a missing signal and returns the outcome.
    ///
    /// # Errors
    /// The signal is incomplete and the type (or P-CHAN-00176, P-CHAN-00268) makes that an
    /// error.
    pub fn finish(self, target_reached: bool) -> Result<MeasurementOutcome, CncMessage> {
        let n = self.axes.len();
        let complete = self.complete();
        if !complete {
            let missing: Vec<String> = self
                .axes
                .iter()
                .enumerate()
                .filter(|(_, a)| a.required && a.latched.is_none())
                .map(|(i, _)| i.to_string())
                .collect();
            if let Some(e) = missing_signal_error(
                self.mtype,
                &self.cfg,
                self.limited_at_sls,
                &missing.join(", "),
            ) {
                return Err(e);
            }
        }
        let contact = contact_path_position(
            self.axes
                .iter()
                .enumerate()
                .filter_map(|(i, a)| a.latched.map(|(p, _)| (i, p))),
            &self.origin,
            &self.dir,
        );
        let mut out = MeasurementOutcome {
            mtype: self.mtype,
            latched: vec![None; n],
            merf: vec![false; n],
            involved: vec![false; n],
            target_reached,
        };
        for (i, a) in self.axes.iter().enumerate() {
            if complete {
                out.involved[i] = a.involved;
                if let Some((p, _)) = a.latched {
                    out.latched[i] = Some(p);
                    out.merf[i] = latched_before_target(contact, self.target_len);
                }
            } else {
                out.involved[i] = a.required;
            }
        }
        Ok(out)
    }
}

/// Where on the measuring line (distance from `origin` along the unit direction `dir`, per
/// axis) the contact lies that the latched positions `(axis, position)` describe: the
/// least-squares projection of the latched axes that move along the line; `None` when no
/// moving axis latched.
pub fn contact_path_position(
    latched: impl IntoIterator<Item = (usize, f64)>,
    origin: &[f64],
    dir: &[f64],
) -> Option<f64> {
    let (mut num, mut den) = (0.0, 0.0);
    for (axis, p) in latched {
        let (Some(&d), Some(&o)) = (dir.get(axis), origin.get(axis)) else {
            continue;
        };
        if d.abs() > 1e-12 {
            num += (p - o) * d;
            den += d * d;
        }
    }
    (den > 0.0).then(|| num / den)
}

/// `V.A.MERF` of a latched axis: the contact (path position from [`contact_path_position`])
/// lies before the programmed target at `target_len` (FCT-C4 §8: "received before the target
/// position is reached"), judged from where the latched positions are, not from where the
/// command was when the latch arrived.
pub fn latched_before_target(contact: Option<f64>, target_len: f64) -> bool {
    contact.is_some_and(|s| s < target_len - CONTACT_AT_TARGET)
}

/// The error of a measuring block that ended without a complete probing signal, naming the
/// `missing` axes; `None` where the type accepts that: type 2 always errs, type 1 with
/// P-CHAN-00176 = 1, type 7 unless P-CHAN-00266 = 1; a path cut at a software limit switch or
/// control-area boundary (P-CHAN-00268) errs with 50706 whatever the type (FCT-C4 §3, §8.2.1).
pub fn missing_signal_error(
    mtype: MeasType,
    cfg: &ChannelMeasConfig,
    limited_at_sls: bool,
    missing: &str,
) -> Option<CncMessage> {
    if limited_at_sls {
        return Some(CncMessage::error(
            ids::MEAS_PATH_LIMITED,
            format!("measurement run stopped at the software limit switch or control-area boundary (P-CHAN-00268) without probing signal (axes {missing})"),
        ));
    }
    match mtype {
        MeasType::Type2 => Some(CncMessage::error(
            ids::MEAS_NO_SIGNAL,
            format!("measurement type 2: probing signal missing (axes {missing})"),
        )),
        MeasType::Type1 if cfg.error_no_signal_type1 => Some(CncMessage::error(
            ids::MEAS_NO_SIGNAL,
            format!("probing signal missing (axes {missing}; P-CHAN-00176 = 1)"),
        )),
        MeasType::Type7 if !cfg.fixed_stop_no_error => Some(CncMessage::error(
            ids::MEAS_NO_FIXED_STOP,
            format!(
                "measurement type 7: fixed stop not detected (axes {missing}; P-CHAN-00266 = 0)"
            ),
        )),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(mtype: MeasType) -> MeasurementRun {
        // X stays at 10 (programmed), Z moves 50 → 0.
        MeasurementRun::new(
            mtype,
            &[10.0, 50.0],
            &[10.0, 0.0],
            &[true, true],
            &[true, true],
            &ChannelMeasConfig::default(),
        )
        .unwrap()
    }

    #[test]
    fn brake_once_when_the_moved_axis_latched() {
        let mut r = run(MeasType::Type1);
        assert_eq!(r.cycle(Nanos(1), &[]), RunStep::Continue);
        // A programmed axis that does not move may latch; it does not complete the signal.
        let x = Latch {
            axis: 0,
            position: 10.0,
        };
        assert_eq!(r.cycle(Nanos(2), &[x]), RunStep::Continue);
        let z = Latch {
            axis: 1,
            position: 20.0,
        };
        assert_eq!(r.cycle(Nanos(3), &[z]), RunStep::Brake);
        // Later latches are not new events.
        let z2 = Latch {
            axis: 1,
            position: 19.0,
        };
        assert_eq!(r.cycle(Nanos(4), &[z2]), RunStep::Continue);
        assert_eq!(r.latched(1), Some((20.0, Nanos(3))));
        let out = r.finish(false).unwrap();
        assert_eq!(out.latched, vec![Some(10.0), Some(20.0)]);
        assert_eq!(out.merf, vec![true, true]);
        assert_eq!(out.involved, vec![true, true]);
    }

    #[test]
    fn type_3_goes_on_to_the_target() {
        let mut r = run(MeasType::Type3);
        let z = Latch {
            axis: 1,
            position: 20.0,
        };
        assert_eq!(r.cycle(Nanos(3), &[z]), RunStep::Continue);
        assert!(r.complete());
        assert!(r.finish(true).unwrap().merf[1]);
    }

    #[test]
    fn a_latch_at_the_target_is_no_merf() {
        let mut r = run(MeasType::Type1);
        r.cycle(
            Nanos(1),
            &[Latch {
                axis: 1,
                position: 0.0,
            }],
        );
        assert!(!r.finish(true).unwrap().merf[1]);
    }

    #[test]
    fn missing_signal_by_type() {
        // Type 1: no error by default, with P-CHAN-00176 = 1 error 900041.
        assert!(run(MeasType::Type1).finish(true).is_ok());
        let cfg = ChannelMeasConfig {
            error_no_signal_type1: true,
            ..ChannelMeasConfig::default()
        };
        let r = MeasurementRun::new(MeasType::Type1, &[0.0], &[5.0], &[true], &[true], &cfg);
        assert_eq!(r.unwrap().finish(true).unwrap_err().id, ids::MEAS_NO_SIGNAL);
        // Type 2 always, and only with one moved axis.
        let r = MeasurementRun::new(
            MeasType::Type2,
            &[0.0],
            &[5.0],
            &[true],
            &[true],
            &ChannelMeasConfig::default(),
        );
        assert_eq!(r.unwrap().finish(true).unwrap_err().id, ids::MEAS_NO_SIGNAL);
        let two = MeasurementRun::new(
            MeasType::Type2,
            &[0.0, 0.0],
            &[5.0, 5.0],
            &[true, true],
            &[true, true],
            &ChannelMeasConfig::default(),
        );
        assert_eq!(two.unwrap_err().id, ids::MEAS_CONFIG);
        // Cut at a software limit switch: 50706.
        let mut r = run(MeasType::Type3);
        r.set_limited_at_sls(true);
        assert_eq!(r.finish(false).unwrap_err().id, ids::MEAS_PATH_LIMITED);
        // Without a complete signal only the moved axes count as involved.
        let out = run(MeasType::Type1).finish(true).unwrap();
        assert_eq!(out.involved, vec![false, true]);
        assert_eq!(out.latched, vec![None, None]);
    }

    #[test]
    fn refused_motions() {
        let cfg = ChannelMeasConfig::default();
        let no_meas = MeasurementRun::new(MeasType::Type1, &[0.0], &[5.0], &[true], &[false], &cfg);
        assert_eq!(no_meas.unwrap_err().id, ids::MEAS_CONFIG);
        let still = MeasurementRun::new(MeasType::Type1, &[0.0], &[0.0], &[true], &[true], &cfg);
        assert_eq!(still.unwrap_err().id, ids::MEAS_CONFIG);
        let fixed = MeasurementRun::new(MeasType::Type7, &[0.0], &[5.0], &[true], &[true], &cfg);
        assert_eq!(fixed.unwrap_err().id, ids::MEAS_CONFIG);
        let short =
            MeasurementRun::new(MeasType::Type1, &[0.0, 1.0], &[5.0], &[true], &[true], &cfg);
        assert_eq!(short.unwrap_err().id, ids::MEAS_CONFIG);
        let nan = MeasurementRun::new(MeasType::Type1, &[f64::NAN], &[5.0], &[true], &[true], &cfg);
        assert_eq!(nan.unwrap_err().id, ids::MEAS_CONFIG);
    }

    #[test]
    fn contact_is_the_projection_onto_the_line() {
        // Line from (0, 0) along (0.6, 0.8); latches at (3, 4): 5 along the line.
        let s = contact_path_position([(0, 3.0), (1, 4.0)], &[0.0, 0.0], &[0.6, 0.8]);
        assert!((s.unwrap() - 5.0).abs() < 1e-12);
        assert_eq!(contact_path_position([], &[0.0], &[1.0]), None);
        assert!(latched_before_target(Some(4.0), 5.0));
        assert!(!latched_before_target(Some(5.0), 5.0));
        assert!(!latched_before_target(None, 5.0));
    }
}
