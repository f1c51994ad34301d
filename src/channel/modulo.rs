//! Modulo rotary axes (P-AXIS-00015 ACHSMODE_MODULO, range P-AXIS-00127 … P-AXIS-00126): once
//! such an axis is at rest — its block, jog or independent motion over — its position is
//! brought into the modulo range by whole ranges, as a CNC's modulo calculation "after the
//! destination position has been reached" (ISG P-AXIS-00015 0x4) does: `G90 A370` ends at 10°,
//! a long continuous jog reads inside [0°, 360°). The drive's position is not changed (the
//! axis keeps the difference, [`crate::axis::Axis::modulo_offset`]); a motion in progress is
//! never wrapped. Seed 001 §1 exempts these axes from SLS monitoring.

use super::{Channel, Mode};

impl Channel {
    /// At the end of a cycle: wrap every modulo axis that is at rest.
    pub(super) fn wrap_modulo_axes(&mut self) {
        let at_rest = match &self.mode {
            Mode::Idle | Mode::WaitAcyclic { .. } | Mode::Aborted => true,
            Mode::Manual(m) => !m.is_moving(),
            _ => false,
        };
        if !at_rest {
            return;
        }
        for i in 0..self.axes.len() {
            let Some((lower, upper)) = self.cfg.axes[i].modulo else {
                continue;
            };
            if self.indp[i].is_some() || self.velocity[i] != 0.0 {
                continue;
            }
            let shift = self.axes[i].wrap_modulo(lower, upper);
            if shift != 0.0 {
                if let Mode::Manual(m) = &mut self.mode {
                    m.shift_start(i, shift);
                }
            }
        }
    }

    /// Axis `i` is a modulo rotary axis: its range `[lower, upper)` (°).
    pub fn modulo_range(&self, i: usize) -> Option<(f64, f64)> {
        self.cfg.axes.get(i).and_then(|c| c.modulo)
    }
}
