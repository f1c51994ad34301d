//! Coordinate frames: PCS, the CS frame, ACS; G92 / G54…G59 zero shifts, the measurement offset
//! MEIN (G101 / G102), tool length and `#CS` (FCT-C4 §4, §5).
//!
//! # The chain
//!
//! ```text
//!        + zero shifts (G92 + G54…G59)            #CS ON[x,y,z,a,b,c]
//! PCS ─────────────────────────────────────► w ───────────────────────► ACS
//!        + MEIN (G101)                            (x,y,z) + R·w on X, Y, Z
//!        + tool length on the tool axis           identity on the other axes
//! ```
//!
//! - **PCS**: the programmed coordinates (`V.A.PROG`).
//! - **w**, the CS frame: `w = PCS + shifts + MEIN (+ tool length on the tool axis)`. This is
//!   what `V.A.ABS` reports (FCT-C4 §5 meas3: `#CS ON[0,0,33,0,0,0]`, MEIN 47 after G101,
//!   `G01 Z100` → `V.A.ABS.Z = 147` while the ACS is 180; meas2 without `#CS`, `G92 Z33`:
//!   `V.A.ABS.Z = 180`, equal to the ACS).
//! - **ACS**: axis coordinates. Without `#CS` (2.5D) the ACS equals `w`. With `#CS` the three
//!   main axes are `ACS = offset + R · w` ([`CsTransform`]); the other axes are `ACS = w`.
//!   There is no kinematic transformation (#TRAFO is out of scope), so the MCS is the ACS.
//!
//! Zero shifts: G92 is ISG's *additive* reference-point offset (`G92 Z33` shifts by +33, FCT-C4
//! §5 meas2); the active zero offset G54…G59 is a table value given by the machine. MEIN is "an
//! additive offset of the programmed position: PCS' = PCS + measurement offset" (§5). The tool
//! length is added on the tool axis in `w`, so under a rotating `#CS` it acts along the CS's
//! tool axis (the tool stands perpendicular to the tilted working plane).
//!
//! Every map is rigid (translations and one rotation), so lines stay lines and a G02/G03 arc in
//! `w` becomes, under a rotating `#CS`, a circle in a tilted plane of the ACS:
//! [`Frames::pcs_to_acs_map`] with [`Segment::transformed`](crate::core::path::Segment::transformed).

mod cs;

pub use cs::CsTransform;

use crate::core::path::{AffineMap, MAX_AXES, MAX_COORDINATE};

/// Why a frame setting was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    /// More axes than [`MAX_AXES`].
    #[error("a channel has at most {max} axes, got {axes}", max = MAX_AXES)]
    TooManyAxes {
        /// Axes given.
        axes: usize,
    },
    /// An axis index is not an axis of the channel.
    #[error("axis {axis} is not one of the channel's {axes} axes")]
    NoSuchAxis {
        /// The index given.
        axis: usize,
        /// Axes of the channel.
        axes: usize,
    },
    /// Two main axes (X, Y, Z) are the same channel axis.
    #[error("channel axis {axis} is given as two main axes")]
    DuplicateMainAxis {
        /// The channel axis.
        axis: usize,
    },
    /// A value is NaN or infinite.
    #[error("{what} is not finite")]
    NonFinite {
        /// Which value.
        what: &'static str,
    },
    /// A value lies beyond ±[`MAX_COORDINATE`].
    #[error("{what} {shown} is beyond ±{max}", shown = crate::messages::show_number(*value), max = MAX_COORDINATE)]
    OutOfRange {
        /// Which value.
        what: &'static str,
        /// The value.
        value: f64,
    },
    /// `#CS ON[...]` with more than six values.
    #[error("#CS ON takes at most 6 values (x, y, z, a, b, c), got {got}")]
    CsArity {
        /// Values given.
        got: usize,
    },
    /// A rotating `#CS` needs all three main axes in the channel.
    #[error("a rotating #CS needs the main axis {axis} in the channel")]
    CsNeedsMainAxes {
        /// The missing main axis (`'X'`, `'Y'` or `'Z'`).
        axis: char,
    },
    /// A table has more entries than the channel has axes.
    #[error("{what} has {got} entries but the channel has {axes} axes")]
    TooManyEntries {
        /// Which table.
        what: &'static str,
        /// Entries given.
        got: usize,
        /// Axes of the channel.
        axes: usize,
    },
}

/// A value that is finite and within ±[`MAX_COORDINATE`].
pub(crate) fn check_value(value: f64, what: &'static str) -> Result<f64, FrameError> {
    if !value.is_finite() {
        return Err(FrameError::NonFinite { what });
    }
    if value.abs() > MAX_COORDINATE {
        return Err(FrameError::OutOfRange { what, value });
    }
    Ok(value)
}

/// The frame state of one channel: zero shifts, MEIN, tool length and `#CS` (module docs).
///
/// All per-axis tables have one entry per channel axis and start at 0. The conversions take
/// slices: they write as many entries as the input, the output and the channel all have, and
/// read a missing input entry on a main axis as 0. They never allocate.
#[derive(Debug, Clone, PartialEq)]
pub struct Frames {
    axes: usize,
    main: [Option<usize>; 3],
    g92: Vec<f64>,
    zero_offset: Vec<f64>,
    mein: Vec<f64>,
    tool_axis: Option<usize>,
    tool_length: f64,
    cs: Option<CsTransform>,
}

const MAIN_NAMES: [char; 3] = ['X', 'Y', 'Z'];

impl Frames {
    /// A channel of `axes` axes; `main` are the channel indices of X, Y, Z (`None`: the channel
    /// has no such axis). The tool axis starts as Z; all offsets are 0, no `#CS`.
    ///
    /// Errors: more than [`MAX_AXES`] axes, a main axis that is not a channel axis, or one
    /// channel axis given twice.
    pub fn new(axes: usize, main: [Option<usize>; 3]) -> Result<Self, FrameError> {
        if axes > MAX_AXES {
            return Err(FrameError::TooManyAxes { axes });
        }
        for (k, m) in main.iter().enumerate() {
            if let Some(axis) = *m {
                if axis >= axes {
                    return Err(FrameError::NoSuchAxis { axis, axes });
                }
                if main[..k].contains(&Some(axis)) {
                    return Err(FrameError::DuplicateMainAxis { axis });
                }
            }
        }
        Ok(Frames {
            axes,
            main,
            g92: vec![0.0; axes],
            zero_offset: vec![0.0; axes],
            mein: vec![0.0; axes],
            tool_axis: main[2],
            tool_length: 0.0,
            cs: None,
        })
    }

    /// A frame set without axes (for callers that must hold one even when [`Frames::new`]
    /// refused the channel).
    pub fn empty() -> Self {
        Frames {
            axes: 0,
            main: [None; 3],
            g92: Vec::new(),
            zero_offset: Vec::new(),
            mein: Vec::new(),
            tool_axis: None,
            tool_length: 0.0,
            cs: None,
        }
    }

    /// Number of channel axes.
    pub fn axes(&self) -> usize {
        self.axes
    }

    /// Channel indices of the main axes X, Y, Z.
    pub fn main_axes(&self) -> [Option<usize>; 3] {
        self.main
    }

    fn check_axis(&self, axis: usize) -> Result<(), FrameError> {
        if axis < self.axes {
            Ok(())
        } else {
            Err(FrameError::NoSuchAxis {
                axis,
                axes: self.axes,
            })
        }
    }

    /// `G92 <axis><value>`: the additive reference-point offset of `axis` (FCT-C4 §5 meas2:
    /// `G92 Z33` → +33). 0 clears it.
    pub fn set_g92(&mut self, axis: usize, value: f64) -> Result<(), FrameError> {
        self.check_axis(axis)?;
        self.g92[axis] = check_value(value, "G92 offset")?;
        Ok(())
    }

    /// The G92 offset of `axis` (0 for an unknown axis).
    pub fn g92(&self, axis: usize) -> f64 {
        self.g92.get(axis).copied().unwrap_or(0.0)
    }

    /// The active zero offset (G54…G59 table row given by the machine), one entry per axis;
    /// missing trailing entries are 0. The whole table is checked before anything changes.
    pub fn set_zero_offset(&mut self, offsets: &[f64]) -> Result<(), FrameError> {
        if offsets.len() > self.axes {
            return Err(FrameError::TooManyEntries {
                what: "zero offset table",
                got: offsets.len(),
                axes: self.axes,
            });
        }
        for &value in offsets {
            check_value(value, "zero offset")?;
        }
        self.zero_offset.fill(0.0);
        self.zero_offset[..offsets.len()].copy_from_slice(offsets);
        Ok(())
    }

    /// The active zero offset of `axis` (0 for an unknown axis).
    pub fn zero_offset(&self, axis: usize) -> f64 {
        self.zero_offset.get(axis).copied().unwrap_or(0.0)
    }

    /// Set the measurement offset MEIN of `axis` (`V.A.MEIN`, FCT-C4 §5; G101 / G102 in
    /// [`g101`](crate::core::measure::results::g101), [`g102`](crate::core::measure::results::g102)).
    pub fn set_mein(&mut self, axis: usize, value: f64) -> Result<(), FrameError> {
        self.check_axis(axis)?;
        self.mein[axis] = check_value(value, "measurement offset")?;
        Ok(())
    }

    /// The measurement offset MEIN of `axis` (0 for an unknown axis).
    pub fn mein(&self, axis: usize) -> f64 {
        self.mein.get(axis).copied().unwrap_or(0.0)
    }

    /// Tool length (mm) along the tool axis; 0 by default.
    pub fn set_tool_length(&mut self, length: f64) -> Result<(), FrameError> {
        self.tool_length = check_value(length, "tool length")?;
        Ok(())
    }

    /// The tool axis (channel index); Z by default.
    pub fn set_tool_axis(&mut self, axis: usize) -> Result<(), FrameError> {
        self.check_axis(axis)?;
        self.tool_axis = Some(axis);
        Ok(())
    }

    /// The tool length on `axis`: the tool length on the tool axis, 0 on the others.
    pub fn tool_length(&self, axis: usize) -> f64 {
        if self.tool_axis == Some(axis) {
            self.tool_length
        } else {
            0.0
        }
    }

    /// `#CS ON[...]` (`Some`) or `#CS OFF` (`None`).
    ///
    /// Errors: a rotating `#CS` while the channel lacks one of X, Y, Z (the map would not be
    /// rigid). A rotation-free `#CS` ignores the offset of a missing main axis.
    pub fn set_cs(&mut self, cs: Option<CsTransform>) -> Result<(), FrameError> {
        if let Some(t) = &cs {
            if t.has_rotation() {
                if let Some(k) = self.main.iter().position(Option::is_none) {
                    return Err(FrameError::CsNeedsMainAxes {
                        axis: MAIN_NAMES[k],
                    });
                }
            }
        }
        self.cs = cs;
        Ok(())
    }

    /// The active `#CS`, if any (`None` is 2.5D).
    pub fn cs(&self) -> Option<&CsTransform> {
        self.cs.as_ref()
    }

    /// The seed's "zero shifts" of `axis`: G92 + the active zero offset (FCT-C4 §5 table).
    pub fn shifts(&self, axis: usize) -> f64 {
        self.g92(axis) + self.zero_offset(axis)
    }

    /// `w − PCS` on `axis`: zero shifts + MEIN + tool length.
    pub fn pcs_offset(&self, axis: usize) -> f64 {
        self.shifts(axis) + self.mein(axis) + self.tool_length(axis)
    }

    fn span(&self, from: &[f64], to: &[f64]) -> usize {
        from.len().min(to.len()).min(self.axes)
    }

    /// PCS → `w` (`+ shifts + MEIN + tool length`); `w` is `V.A.ABS`.
    pub fn pcs_to_w(&self, pcs: &[f64], w: &mut [f64]) {
        let n = self.span(pcs, w);
        for (i, (o, p)) in w[..n].iter_mut().zip(pcs).enumerate() {
            *o = p + self.pcs_offset(i);
        }
    }

    /// `w` → PCS (`− shifts − MEIN − tool length`).
    pub fn w_to_pcs(&self, w: &[f64], pcs: &mut [f64]) {
        let n = self.span(w, pcs);
        for (i, (o, p)) in pcs[..n].iter_mut().zip(w).enumerate() {
            *o = p - self.pcs_offset(i);
        }
    }

    fn main_of(&self, v: &[f64]) -> [f64; 3] {
        self.main
            .map(|m| m.and_then(|i| v.get(i)).copied().unwrap_or(0.0))
    }

    fn put_main(&self, out: &mut [f64], v: [f64; 3]) {
        for (m, value) in self.main.iter().zip(v) {
            if let Some(o) = m.and_then(|i| out.get_mut(i)) {
                *o = value;
            }
        }
    }

    /// `w` → ACS: `#CS` on the main axes, identity elsewhere and in 2.5D.
    pub fn w_to_acs(&self, w: &[f64], acs: &mut [f64]) {
        let n = self.span(w, acs);
        acs[..n].copy_from_slice(&w[..n]);
        if let Some(cs) = &self.cs {
            let out = cs.to_acs(self.main_of(w));
            self.put_main(&mut acs[..n], out);
        }
    }

    /// ACS → `w`: the inverse of [`Frames::w_to_acs`].
    pub fn acs_to_w(&self, acs: &[f64], w: &mut [f64]) {
        let n = self.span(acs, w);
        w[..n].copy_from_slice(&acs[..n]);
        if let Some(cs) = &self.cs {
            let out = cs.to_cs(self.main_of(acs));
            self.put_main(&mut w[..n], out);
        }
    }

    /// PCS → ACS.
    pub fn pcs_to_acs(&self, pcs: &[f64], acs: &mut [f64]) {
        let mut w = [0.0; MAX_AXES];
        let n = self.span(pcs, acs);
        self.pcs_to_w(&pcs[..n], &mut w[..n]);
        self.w_to_acs(&w[..n], &mut acs[..n]);
    }

    /// ACS → PCS.
    pub fn acs_to_pcs(&self, acs: &[f64], pcs: &mut [f64]) {
        let mut w = [0.0; MAX_AXES];
        let n = self.span(acs, pcs);
        self.acs_to_w(&acs[..n], &mut w[..n]);
        self.w_to_pcs(&w[..n], &mut pcs[..n]);
    }

    /// A direction in `w` (or the PCS: the shifts are translations) → ACS: `R · d` on the main
    /// axes, identity elsewhere.
    pub fn dir_to_acs(&self, d: &[f64], out: &mut [f64]) {
        let n = self.span(d, out);
        out[..n].copy_from_slice(&d[..n]);
        if let Some(cs) = &self.cs {
            let v = cs.apply_dir(self.main_of(d));
            self.put_main(&mut out[..n], v);
        }
    }

    /// The PCS → ACS map, for [`Segment::transformed`](crate::core::path::Segment::transformed).
    pub fn pcs_to_acs_map(&self) -> ToAcs<'_> {
        ToAcs {
            frames: self,
            from_pcs: true,
        }
    }

    /// The `w` → ACS map (`#CS` only), for
    /// [`Segment::transformed`](crate::core::path::Segment::transformed).
    pub fn w_to_acs_map(&self) -> ToAcs<'_> {
        ToAcs {
            frames: self,
            from_pcs: false,
        }
    }
}

/// [`Frames`] seen as the rigid map PCS → ACS or `w` → ACS ([`Frames::pcs_to_acs_map`],
/// [`Frames::w_to_acs_map`]).
#[derive(Debug, Clone, Copy)]
pub struct ToAcs<'a> {
    frames: &'a Frames,
    from_pcs: bool,
}

impl AffineMap for ToAcs<'_> {
    fn map_point(&self, p: &[f64], out: &mut [f64]) {
        if self.from_pcs {
            self.frames.pcs_to_acs(p, out);
        } else {
            self.frames.w_to_acs(p, out);
        }
    }

    fn map_vector(&self, d: &[f64], out: &mut [f64]) {
        self.frames.dir_to_acs(d, out);
    }
}
