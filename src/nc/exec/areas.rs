//! `#CONTROL AREA` and the motion blocks of an area definition (FCT-C14 §3).
//!
//! Between BEGIN and END a motion block defines geometry and does not move the axes. Its
//! programmed coordinates are turned into MCS coordinates with the frames of the moment (zero
//! offsets G54…, G92, MEIN, tool length) but without `#CS` (FCT-C14 §2.3 notice, §3.1
//! attention), and handed to the channel's area table as a [`DefBlock`]. Which coordinates
//! form the area plane depends on the BEGIN bracket and on the active machining plane (seed
//! §3.1.1 "the first two main axes of the active machining plane"): for MCS areas X / Y (G17),
//! Z / X (G18), Y / Z (G19); for `MONITOR_LVL=IMCS` (seed §2.4) U / V, W / U, V / W; `X2=` /
//! `Y2=` words always go to the additional-axes plane (seed §4). The centre is the pair of
//! `I` / `J` / `K` that belongs to the plane, as for G02 / G03 (G17: I, J; G18: K, I; G19: J,
//! K; G162: relative to the previous definition point, G161: absolute). A G00 block needs no F
//! (rapid has its own velocity).

use super::{err, Executor, Fail, MotionMode, Plane};
use crate::channel::Channel;
use crate::core::monitor::area_geom::Plane as AreaPlane;
use crate::core::monitor::areas::{
    plane_axis_names, AreaAxes, AreaCommand, DefBlock, DefMotion, MonitorLevel,
};
use crate::messages::{ids, BlockRef};

/// An open definition as the executor sees it.
#[derive(Debug, Clone)]
pub(super) struct OpenArea {
    level: MonitorLevel,
    /// Programmed (PCS) position of the definition chain, per channel axis.
    pcs: Vec<f64>,
}

impl Executor {
    /// `#CONTROL AREA …`.
    pub(super) fn area_command(&mut self, cmd: &AreaCommand, ch: &mut Channel) -> Result<(), Fail> {
        if !ch.area_command(cmd) {
            return Err(Fail::Queued);
        }
        match cmd {
            AreaCommand::Begin(h) => {
                self.area_def = Some(OpenArea {
                    level: h.monitor_level,
                    pcs: self.prog.clone(),
                })
            }
            AreaCommand::End => self.area_def = None,
            _ => {}
        }
        Ok(())
    }

    /// A definition is open in the channel.
    pub(super) fn defining(&self, ch: &Channel) -> bool {
        self.area_def.is_some() && ch.area_defining()
    }

    /// One motion block of an open definition.
    pub(super) fn area_definition_block(
        &mut self,
        at: BlockRef,
        axes: &[(usize, f64)],
        centre: &[Option<f64>; 3],
        meas_g: Option<u32>,
        has_independent: bool,
        ch: &mut Channel,
    ) -> Result<(), Fail> {
        let Some(open) = self.area_def.clone() else {
            return Ok(());
        };
        let motion = match (meas_g, has_independent, self.modal.motion) {
            (Some(_), _, _) | (_, true, _) => DefMotion::Other,
            (None, false, MotionMode::G0) => DefMotion::G00,
            (None, false, MotionMode::G1) => DefMotion::G01,
            (None, false, MotionMode::G2) => DefMotion::G02,
            (None, false, MotionMode::G3) => DefMotion::G03,
        };
        let plane = match self.modal.plane {
            Plane::G17 => AreaPlane::G17,
            Plane::G18 => AreaPlane::G18,
            Plane::G19 => AreaPlane::G19,
        };
        let (c1, c2, _) = plane.axes();
        let [n1, n2, _] = plane_axis_names(open.level, AreaAxes::Main, plane);
        let (p, q) = match open.level {
            MonitorLevel::Mcs => (self.main[c1], self.main[c2]),
            MonitorLevel::Imcs => (self.axis(n1), self.axis(n2)),
        };
        let (x2, y2) = (self.axis("X2"), self.axis("Y2"));
        let Some((p, q)) = p.zip(q) else {
            let level = match open.level {
                MonitorLevel::Mcs => "",
                MonitorLevel::Imcs => " MONITOR_LVL=IMCS",
            };
            return Err(err(
                ids::AREA_AXES,
                format!(
                    "control area{level}: the plane {plane} needs the axes {n1} and {n2}, \
                     the channel lacks one"
                ),
            ));
        };
        let start = open.pcs.clone();
        let mut pcs = open.pcs.clone();
        for &(i, v) in axes {
            pcs[i] = if self.modal.absolute { v } else { pcs[i] + v };
        }
        let mut w = vec![0.0; pcs.len()];
        self.frames.pcs_to_w(&pcs, &mut w);
        let programmed = |i: Option<usize>| i.filter(|i| axes.iter().any(|(k, _)| k == i));
        let mut b = DefBlock::new(at, motion)
            .plane(plane)
            .absolute(self.modal.absolute)
            .feed_valid(self.modal.feed.is_some() || motion == DefMotion::G00);
        b.main = [
            programmed(Some(p)).map(|i| w[i]),
            programmed(Some(q)).map(|i| w[i]),
        ];
        b.additional = [programmed(x2).map(|i| w[i]), programmed(y2).map(|i| w[i])];
        if centre[c1].is_some() || centre[c2].is_some() {
            let (ci, cj) = (centre[c1].unwrap_or(0.0), centre[c2].unwrap_or(0.0));
            let mut c = start.clone();
            if self.modal.centre_absolute {
                c[p] = ci;
                c[q] = cj;
            } else {
                c[p] += ci;
                c[q] += cj;
            }
            let mut cw = vec![0.0; c.len()];
            self.frames.pcs_to_w(&c, &mut cw);
            b = b.centre(cw[p], cw[q]);
        }
        if !ch.area_definition_block(&b) {
            self.area_def = None;
            return Err(Fail::Queued);
        }
        if let Some(o) = self.area_def.as_mut() {
            o.pcs = pcs;
        }
        Ok(())
    }
}
