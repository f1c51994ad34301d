//! Measurement results: `V.A.MESS`, `V.A.MERF`, `V.A.MOFFS`, `V.A.MEAS.ACS.VALUE`,
//! `V.A.MEAS.PCS.VALUE` and the measurement offset `V.A.MEIN` with G101 / G102 (FCT-C4 §4, §5).
//!
//! Pure functions over [`Frames`]: [`compute`] turns the latched ACS positions of a measuring
//! block into per-axis results, [`g101`] and [`g102`] set MEIN.
//!
//! # The relationships (FCT-C4 §5 table; 2.5D and `#CS`, #TRAFO is out of scope)
//!
//! With `w` the CS frame of [`crate::core::frames`] (`w = ACS` in 2.5D, `w = Rᵀ·(ACS − offset)`
//! on X, Y, Z under `#CS`):
//!
//! | value | 2.5D | `#CS ON` | here |
//! |---|---|---|---|
//! | `MESS` | ACS position (all offsets) | ACS converted into the active CS, incl. offsets | `w` |
//! | `MEAS.ACS.VALUE` | ACS position | ACS position | the latch |
//! | `MEAS.PCS.VALUE` | ACS without offsets | ACS converted into the CS, without offsets | `w − shifts − MEIN − tool length` (+ ball) |
//! | `MOFFS` | `MESS − PROG − zero shifts − tool offset` | same | same |
//!
//! Checked against §5 meas1–meas4 (`tests/it/frames_results.rs`): meas2 (`G92 Z33`, latch at 100)
//! gives MESS 100, PCS 67, MOFFS `100 − 20 − 33 = 47`; meas3 (`#CS ON[0,0,33,0,0,0]`) MESS 67;
//! meas4 (`#CS ON[0,0,75,0,15,0]`, latch at ACS Z 55.5) MESS ≈ 20, MOFFS ≈ 30.
//!
//! # Interpretations
//!
//! - **MEIN in the PCS value.** In meas1–meas4 MEIN is 0 whenever a measurement is taken, so the
//!   seed does not show whether `MEAS.PCS.VALUE` subtracts it. It is subtracted here, with the
//!   tool length: the PCS value is "without offsets" (§5), MEIN "acts as an additive offset of
//!   the programmed position", so the PCS value is the exact inverse of the frame chain and
//!   compares directly with programmed coordinates. `MOFFS` follows the table literally and does
//!   *not* subtract MEIN: then `G101 <axis>1` sets MEIN so that the programmed target maps onto
//!   the measured point, whatever MEIN was before.
//! - **Probe ball.** With a ball radius `r` (tool radius of the active D; P-CHAN-00311 = 0
//!   includes it), the PCS value is the contact point `ball centre + r · (unit direction of the
//!   measuring motion in the PCS)` on X, Y, Z. Example (§5 "Measuring with a measuring probe tool
//!   of 2mm radius", whose figure the seed lacks): `G100 Z20` from above, `r = 2`, latch at ACS
//!   Z 100 → PCS value 98. MESS, the ACS value and MOFFS stay ball-centre values (the seed names
//!   the radius only for the PCS value).
//! - **Which axes get new values.** 2.5D: a programmed axis with a latch gets a new result, a
//!   programmed axis without one gets `None` (`V.A.MERF` false, no measured value), a
//!   non-programmed axis keeps its previous result (§5 Notice). Under `#CS` the three main axes
//!   are latched and converted jointly (§4): all of them must have latched, and then all three
//!   get new results whether programmed or not; none latched is a measurement without a probing
//!   signal; some but not all is [`ResultsError::IncompleteCsLatch`].

use crate::core::frames::{check_value, FrameError, Frames};
use crate::core::path::MAX_AXES;

/// The results of one axis. `V.A.MERF` is whether an axis has a result
/// (`Option<AxisResult>::is_some`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisResult {
    /// `V.A.MESS`: the measured position in the frame the measurement took place in, all
    /// offsets included (`w`).
    pub mess: f64,
    /// `V.A.MEAS.ACS.VALUE`: the latched ACS position.
    pub acs: f64,
    /// `V.A.MEAS.PCS.VALUE`: the measured position in the PCS, without offsets, with the probe
    /// ball's contact correction.
    pub pcs: f64,
    /// `V.A.MOFFS`: `MESS − PROG − zero shifts − tool offset`.
    pub moffs: f64,
}

/// The measuring block (G100) the latches belong to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuringBlock<'a> {
    /// Target point of the block in the PCS (`V.A.PROG`), one entry per channel axis
    /// (non-programmed axes at their current programmed position).
    pub target_pcs: &'a [f64],
    /// Axes programmed in the block, one entry per channel axis.
    pub programmed: &'a [bool],
    /// Direction of the measuring motion on X, Y, Z in the PCS (need not be unit length; zero:
    /// no ball correction). [`motion_direction`] makes it from the start and target points.
    pub direction_pcs: [f64; 3],
    /// Ball radius of the probe (tool radius of the active D, mm, ≥ 0).
    pub ball_radius: f64,
    /// Whether the ball radius enters the PCS value (P-CHAN-00311 = 0, the default).
    pub include_radius: bool,
}

/// Why results could not be computed or an offset not set.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ResultsError {
    /// A per-axis slice does not have one entry per channel axis.
    #[error("{what} has {got} entries but the channel has {axes} axes")]
    Length {
        /// Which input.
        what: &'static str,
        /// Entries given.
        got: usize,
        /// Axes of the channel.
        axes: usize,
    },
    /// A latched position or target coordinate is NaN or infinite.
    #[error("{what} of axis {axis} is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Channel axis.
        axis: usize,
    },
    /// The ball radius is NaN, infinite or negative.
    #[error("probe ball radius {radius} must be finite and not negative")]
    InvalidRadius {
        /// The radius given.
        radius: f64,
    },
    /// Under `#CS` some but not all main axes latched (FCT-C4 §4: the probing signal must be
    /// looped to all measurement axes).
    #[error("#CS active: main axis {axis} has no probing latch while others have")]
    IncompleteCsLatch {
        /// Channel index of a main axis without a latch.
        axis: usize,
    },
    /// G101 for an axis without a measured value (FCT-C4 §5: "An error message is output if
    /// no measured values were detected beforehand").
    #[error("G101: axis {axis} has no measured value")]
    NoMeasuredValue {
        /// Channel axis.
        axis: usize,
    },
    /// G101 with a factor that is not finite.
    #[error("G101: factor {factor} of axis {axis} is not finite")]
    InvalidFactor {
        /// Channel axis.
        axis: usize,
        /// The factor.
        factor: f64,
    },
    /// A frame refused the value (unknown axis, MEIN out of range).
    #[error(transparent)]
    Frame(#[from] FrameError),
}

fn check_len(what: &'static str, got: usize, axes: usize) -> Result<(), ResultsError> {
    if got == axes {
        Ok(())
    } else {
        Err(ResultsError::Length { what, got, axes })
    }
}

/// `target − start` on X, Y, Z (0 for a missing main axis or entry): the
/// [`MeasuringBlock::direction_pcs`] of a straight measuring motion.
pub fn motion_direction(frames: &Frames, start_pcs: &[f64], target_pcs: &[f64]) -> [f64; 3] {
    frames.main_axes().map(|m| match m {
        Some(i) => match (start_pcs.get(i), target_pcs.get(i)) {
            (Some(s), Some(t)) => t - s,
            _ => 0.0,
        },
        None => 0.0,
    })
}

/// The unit direction, or `None` for a zero or non-finite one.
fn unit(d: [f64; 3]) -> Option<[f64; 3]> {
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    (n.is_finite() && n > 0.0 && d.iter().all(|x| x.is_finite())).then(|| d.map(|x| x / n))
}

/// The results of a measuring block (FCT-C4 §5 table; module docs).
///
/// `latched_acs` has the latched ACS position per channel axis (`None`: no latch), `previous`
/// the results before the block; both, like the block's slices, one entry per channel axis.
///
/// Errors: wrong slice lengths, a non-finite latch or target, an invalid ball radius, an
/// incomplete latch of the main axes under `#CS`.
pub fn compute(
    frames: &Frames,
    block: &MeasuringBlock<'_>,
    latched_acs: &[Option<f64>],
    previous: &[Option<AxisResult>],
) -> Result<Vec<Option<AxisResult>>, ResultsError> {
    let n = frames.axes();
    check_len("latched positions", latched_acs.len(), n)?;
    check_len("previous results", previous.len(), n)?;
    check_len("target point", block.target_pcs.len(), n)?;
    check_len("programmed axes", block.programmed.len(), n)?;
    for (axis, t) in block.target_pcs.iter().enumerate() {
        if !t.is_finite() {
            return Err(ResultsError::NonFinite {
                what: "target",
                axis,
            });
        }
    }
    let mut acs = [0.0; MAX_AXES];
    for (axis, (slot, latch)) in acs.iter_mut().zip(latched_acs).enumerate() {
        if let Some(p) = *latch {
            if !p.is_finite() {
                return Err(ResultsError::NonFinite {
                    what: "latched position",
                    axis,
                });
            }
            *slot = p;
        }
    }
    let radius = block.ball_radius;
    if !(radius.is_finite() && radius >= 0.0) {
        return Err(ResultsError::InvalidRadius { radius });
    }

    let main = frames.main_axes();
    let is_main = |i: usize| main.contains(&Some(i));
    // Under #CS the main axes latch and convert together (§4).
    let cs_fresh = if frames.cs().is_some() {
        let present = main.iter().flatten();
        match present.clone().find(|&&i| latched_acs[i].is_none()) {
            None => main.iter().any(Option::is_some),
            Some(&missing) if present.clone().any(|&i| latched_acs[i].is_some()) => {
                return Err(ResultsError::IncompleteCsLatch { axis: missing });
            }
            Some(_) => false,
        }
    } else {
        false
    };

    let mut w = [0.0; MAX_AXES];
    let mut pcs = [0.0; MAX_AXES];
    frames.acs_to_w(&acs[..n], &mut w[..n]);
    frames.w_to_pcs(&w[..n], &mut pcs[..n]);
    if let (true, Some(dir)) = (block.include_radius, unit(block.direction_pcs)) {
        for (m, d) in main.iter().zip(dir) {
            if let Some(i) = *m {
                pcs[i] += radius * d;
            }
        }
    }

    let results = (0..n)
        .map(|i| {
            let joint = frames.cs().is_some() && is_main(i);
            let fresh = if joint {
                cs_fresh
            } else {
                block.programmed[i] && latched_acs[i].is_some()
            };
            if fresh {
                Some(AxisResult {
                    mess: w[i],
                    acs: acs[i],
                    pcs: pcs[i],
                    moffs: w[i] - block.target_pcs[i] - frames.shifts(i) - frames.tool_length(i),
                })
            } else if block.programmed[i] {
                None
            } else {
                previous[i]
            }
        })
        .collect();
    Ok(results)
}

/// `G101 <axis><factor> …`: `MEIN = factor × MOFFS` for each listed axis (FCT-C4 §5, "Include
/// the measurement offset in calculations with G101, G102"; meas1: `G101 Z1` after MOFFS 80 →
/// MEIN 80). Everything is checked before any MEIN changes.
///
/// Errors: an unknown axis, an axis without a measured value, a non-finite factor, a MEIN
/// beyond range.
pub fn g101(
    frames: &mut Frames,
    results: &[Option<AxisResult>],
    factors: &[(usize, f64)],
) -> Result<(), ResultsError> {
    let mut values = Vec::with_capacity(factors.len());
    for &(axis, factor) in factors {
        if axis >= frames.axes() {
            return Err(FrameError::NoSuchAxis {
                axis,
                axes: frames.axes(),
            }
            .into());
        }
        if !factor.is_finite() {
            return Err(ResultsError::InvalidFactor { axis, factor });
        }
        let result = results
            .get(axis)
            .copied()
            .flatten()
            .ok_or(ResultsError::NoMeasuredValue { axis })?;
        values.push((
            axis,
            check_value(factor * result.moffs, "measurement offset")?,
        ));
    }
    for (axis, value) in values {
        frames.set_mein(axis, value)?;
    }
    Ok(())
}

/// `G102 <axis> …`: MEIN = 0 for each listed axis (FCT-C4 §5). All axes are checked first.
///
/// Errors: an unknown axis.
pub fn g102(frames: &mut Frames, axes: &[usize]) -> Result<(), ResultsError> {
    for &axis in axes {
        if axis >= frames.axes() {
            return Err(FrameError::NoSuchAxis {
                axis,
                axes: frames.axes(),
            }
            .into());
        }
    }
    for &axis in axes {
        frames.set_mein(axis, 0.0)?;
    }
    Ok(())
}
