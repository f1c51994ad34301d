//! Motion blocks: PCS targets through the frames to the ACS, arcs (mapped exactly under a
//! rotating `#CS`), measuring blocks (G100 / G210 / G310) and independent-axis motions.

use super::{err, Executor, Fail, MotionMode, PendingMeasurement, Plane};
use crate::channel::{Channel, MeasureRequest, MotionKind, MotionRequest, Prepared};
use crate::core::measure::MeasType;
use crate::core::path::Segment;
use crate::messages::ids;
use crate::nc::ast::{IndependentMotion, Span};

impl Executor {
    /// The path motion of a block, if it has one. Returns whether a motion started.
    pub(super) fn motion_block(
        &mut self,
        axes: &[(usize, f64)],
        centre: &[Option<f64>; 3],
        meas_g: Option<u32>,
        ch: &mut Channel,
        measured: &mut [bool],
    ) -> Result<bool, Fail> {
        let is_arc =
            matches!(self.modal.motion, MotionMode::G2 | MotionMode::G3) && meas_g.is_none();
        if axes.is_empty() && !(is_arc && centre.iter().any(Option::is_some)) {
            if meas_g.is_some() && axes.is_empty() {
                // G100 with only independent axes: nothing for the path.
                return Ok(false);
            }
            return Ok(false);
        }
        let n = self.prog.len();
        let mut prog = self.prog.clone();
        for &(i, v) in axes {
            prog[i] = if self.modal.absolute { v } else { prog[i] + v };
        }
        let mut target = vec![0.0; n];
        self.frames.pcs_to_acs(&prog, &mut target);
        let mut programmed = vec![false; n];
        for &(i, _) in axes {
            programmed[i] = true;
        }
        // An axis still moving as an independent axis (`INDP_ASYN`) that this block does not
        // program goes on beside the path (FCT-C4 §2: independent axes move "in parallel to a
        // path motion"): the path leaves it where it is, its programmed position stays the
        // independent motion's target.
        let commands = ch.command_positions();
        for (i, t) in target.iter_mut().enumerate() {
            if !programmed[i] && ch.moving_independently(i) {
                *t = commands[i];
            }
        }
        let feed = match (self.modal.motion, meas_g) {
            (MotionMode::G0, None) => 0.0,
            // Measurement type 2 travels with P-AXIS-00215 of its axis, not with F (FCT-C4 §3
            // "Measurement feed is specified in the axis data list", §8.2.2 P-AXIS-00215): an F
            // is neither needed nor used.
            (_, Some(_)) if self.modal.meas_type == MeasType::Type2 => {
                self.modal.feed.unwrap_or(0.0)
            }
            _ => self.modal.feed.ok_or_else(|| {
                err(
                    ids::NC_NO_FEED,
                    "no feed programmed (F) for a G01/G02/G03/G100 block",
                )
            })?,
        };
        let (kind, measure) = match meas_g {
            Some(g) => {
                let m = MeasureRequest {
                    mtype: self.modal.meas_type,
                    gcode: g,
                    cs_active: self.frames.cs().is_some(),
                    programmed: programmed.clone(),
                    overrides: self.overrides.clone(),
                };
                (MotionKind::Linear, Some(m))
            }
            None => match self.modal.motion {
                MotionMode::G0 => (MotionKind::Rapid, None),
                MotionMode::G1 => (MotionKind::Linear, None),
                MotionMode::G2 | MotionMode::G3 => (self.arc_kind(centre, &prog)?, None),
            },
        };
        let start_pcs = self.prog.clone();
        let is_meas = measure.is_some();
        let req = MotionRequest {
            kind,
            target,
            feed,
            measure,
        };
        match ch.start_motion(&req) {
            Prepared::Started => {
                // V.A.PROG: the target point of a measuring block, until the next motion block.
                for (t, (p, &programmed)) in self
                    .meas_target
                    .iter_mut()
                    .zip(prog.iter().zip(&programmed))
                {
                    *t = (is_meas && programmed).then_some(*p);
                }
                if is_meas {
                    for (m, p) in measured.iter_mut().zip(&programmed) {
                        *m |= *p;
                    }
                    self.pending_meas = Some(PendingMeasurement {
                        direction_pcs: crate::core::measure::results::motion_direction(
                            &self.frames,
                            &start_pcs,
                            &prog,
                        ),
                        target_pcs: prog.clone(),
                        programmed,
                    });
                }
                self.prog = prog;
                Ok(true)
            }
            Prepared::Empty => {
                self.meas_target.iter_mut().for_each(|t| *t = None);
                self.prog = prog;
                Ok(false)
            }
            Prepared::Rejected => Err(Fail::Queued),
        }
    }

    /// G02 / G03 in the active plane. Without a rotating `#CS` the arc lies in an axis plane of
    /// the ACS; with one, it is built in the PCS and mapped exactly into a tilted plane.
    fn arc_kind(&self, centre: &[Option<f64>; 3], prog: &[f64]) -> Result<MotionKind, Fail> {
        // (a1, a2) and which of I/J/K belong to them, per plane (DIN 66025).
        let (a1, a2, c1, c2) = match self.modal.plane {
            Plane::G17 => (self.main[0], self.main[1], 0, 1),
            Plane::G18 => (self.main[2], self.main[0], 2, 0),
            Plane::G19 => (self.main[1], self.main[2], 1, 2),
        };
        let (Some(a1), Some(a2)) = (a1, a2) else {
            return Err(err(
                ids::NC_ARC_GEOMETRY,
                "G02/G03: the channel lacks a main axis of the active plane",
            ));
        };
        let o1 = centre[c1].unwrap_or(0.0);
        let o2 = centre[c2].unwrap_or(0.0);
        let centre_offset = if self.modal.centre_absolute {
            // G161: absolute PCS centre → offset from the start point.
            [o1 - self.prog[a1], o2 - self.prog[a2]]
        } else {
            [o1, o2]
        };
        let clockwise = self.modal.motion == MotionMode::G2;
        let rotating = self.frames.cs().is_some_and(|c| c.has_rotation());
        if !rotating {
            return Ok(MotionKind::Arc {
                a1,
                a2,
                centre_offset,
                clockwise,
            });
        }
        let arc = Segment::arc(
            self.prog.clone(),
            prog.to_vec(),
            a1,
            a2,
            centre_offset,
            clockwise,
            crate::channel::ARC_RADIUS_TOLERANCE,
        )
        .map_err(|e| err(ids::NC_ARC_GEOMETRY, e.to_string()))?;
        let mapped = arc
            .transformed(&self.frames.pcs_to_acs_map())
            .map_err(|e| err(ids::NC_ARC_GEOMETRY, format!("#CS: {e}")))?;
        Ok(MotionKind::Path(mapped))
    }

    /// `X[INDP_SYN G100 G90 POS100 FEED500]` (FCT-C4 §2).
    pub(super) fn independent(
        &mut self,
        name: &str,
        motion: &IndependentMotion,
        span: Span,
        block_meas: Option<u32>,
        ch: &mut Channel,
        measured: &mut [bool],
    ) -> Result<(), Fail> {
        let i = self
            .axis(name)
            .ok_or_else(|| err(ids::NC_EVALUATION, format!("unknown axis '{name}'")))?;
        if self.frames.cs().is_some_and(|c| c.has_rotation()) {
            return Err(err(
                ids::NC_UNSUPPORTED,
                format!("independent axis {name} under a rotating #CS is not supported"),
            ));
        }
        let mut absolute = self.modal.absolute;
        let mut meas = false;
        for g in &motion.gcodes {
            match g {
                90 => absolute = true,
                91 => absolute = false,
                100 => meas = true,
                0 | 1 => {}
                other => {
                    return Err(err(
                        ids::NC_UNSUPPORTED,
                        format!("G{other} is not allowed in an independent-axis motion (G00 G01 G90 G91 G100)"),
                    ))
                }
            }
        }
        let _ = block_meas;
        let pos = self.num(&motion.pos, span, ch)?;
        // Type 2 travels with P-AXIS-00215, not with FEED / F (FCT-C4 §3, §8.2.2).
        let type2 = meas && self.modal.meas_type == MeasType::Type2;
        let feed = match (&motion.feed, self.modal.feed) {
            (Some(f), _) => {
                let feed = self.num(f, span, ch)?;
                if feed.is_nan() || feed <= 0.0 {
                    return Err(err(
                        ids::NC_NO_FEED,
                        format!("independent axis {name}: FEED{feed} must be > 0"),
                    ));
                }
                feed
            }
            // The modal F was checked (> 0) where it was programmed.
            (None, Some(f)) => f,
            (None, None) if type2 => 0.0,
            (None, None) => {
                return Err(err(
                    ids::NC_NO_FEED,
                    format!("independent axis {name}: no FEED"),
                ))
            }
        };
        let target_pcs = if absolute { pos } else { self.prog[i] + pos };
        let mut prog = self.prog.clone();
        prog[i] = target_pcs;
        let mut acs = vec![0.0; prog.len()];
        self.frames.pcs_to_acs(&prog, &mut acs);
        let measure = meas.then(|| MeasureRequest {
            mtype: self.modal.meas_type,
            gcode: 100,
            cs_active: false,
            programmed: (0..prog.len()).map(|k| k == i).collect(),
            overrides: self.overrides.clone(),
        });
        let start_pcs = self.prog.clone();
        match ch.start_independent(i, acs[i], feed, motion.sync, measure) {
            Prepared::Started | Prepared::Empty => {
                if meas {
                    measured[i] = true;
                    let pm = self.pending_meas.get_or_insert_with(|| PendingMeasurement {
                        target_pcs: start_pcs.clone(),
                        programmed: vec![false; start_pcs.len()],
                        direction_pcs: [0.0; 3],
                    });
                    pm.target_pcs[i] = target_pcs;
                    pm.programmed[i] = true;
                }
                if let Some(t) = self.meas_target.get_mut(i) {
                    *t = meas.then_some(target_pcs);
                }
                self.prog[i] = target_pcs;
                Ok(())
            }
            Prepared::Rejected => Err(Fail::Queued),
        }
    }
}
