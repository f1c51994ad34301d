//! Arcs in a general plane of the n-space and the rigid maps that make them.
//!
//! Under a rotating `#CS` (FCT-C4 §4, §5 meas4) a G02/G03 arc programmed in a plane of two
//! axes becomes a circle in a tilted plane of the ACS. [`Segment::transformed`] maps a segment
//! through an [`AffineMap`] (for example [`Frames::pcs_to_acs_map`]): lines to lines, arcs to
//! arcs with a [`SpaceArc`] geometry, exactly (no sampling).
//!
//! # Geometry
//!
//! With the fraction `f = s / length` in `[0, 1]` and the angle `θ = start_angle + f · sweep`:
//!
//! ```text
//! p(f) = centre + r · (cos θ · u + sin θ · v) + f · (helix + miss)
//! ```
//!
//! `u`, `v` are orthonormal n-vectors spanning the circle's plane; `helix` is orthogonal to them
//! (the linearly moving axes of a helix, mapped); `miss` lies in the plane (the radius-mismatch
//! correction of the module docs of [`crate::core::path`], mapped).
//!
//! Per axis `k`, `r · (u_k cos θ + v_k sin θ) = r·A_k·cos(θ − φ_k)` with
//! `A_k = √(u_k² + v_k²)` and `φ_k = atan2(v_k, u_k)`. With `d_k = helix_k + miss_k` the
//! derivative `dp_k/df = −r·A_k·sweep·sin(θ − φ_k) + d_k` vanishes where
//! `sin(θ − φ_k) = d_k / (r·A_k·sweep)`; [`Segment::extent`] evaluates the ends and every such
//! angle inside the sweep (without a helix: `φ_k` and `φ_k + π`), which is exact.
//!
//! [`Frames::pcs_to_acs_map`]: crate::core::frames::Frames::pcs_to_acs_map

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use super::{check_dims, check_values, Arc, PathError, Segment, ANGLE_SLACK};

/// Tolerance (relative to `max(1, scale)`) within which a map counts as rigid.
const RIGID_TOLERANCE: f64 = 1e-9;

/// An affine map of the n-space, `p ↦ A·p + b`: [`Segment::transformed`] needs it rigid (a
/// rotation plus a translation), such as the frame maps of [`crate::core::frames`].
///
/// Both methods write one entry per axis into `out` (which has as many entries as the input).
pub trait AffineMap {
    /// `out = A·p + b`.
    fn map_point(&self, p: &[f64], out: &mut [f64]);
    /// `out = A·d` (the linear part only).
    fn map_vector(&self, d: &[f64], out: &mut [f64]);
}

/// The geometry of an arc in a general plane (module docs): set by [`Segment::transformed`],
/// or from a plane arc by [`Arc::to_space`]. All vectors have one entry per axis.
#[derive(Debug, Clone, PartialEq)]
pub struct SpaceArc {
    /// Centre of the circle at the start of the arc (the helix moves it by `helix`).
    pub centre: Vec<f64>,
    /// Unit vector from the centre towards angle 0.
    pub u: Vec<f64>,
    /// Unit vector towards angle π/2, orthogonal to `u`; a positive sweep turns from `u` to `v`.
    pub v: Vec<f64>,
    /// Displacement of the linearly moving part over the whole arc, orthogonal to `u` and `v`.
    pub helix: Vec<f64>,
    /// Radius-mismatch correction reached at the end, in the plane of `u` and `v` (zero for an
    /// exact circle).
    pub miss: Vec<f64>,
}

fn get(v: &[f64], k: usize) -> f64 {
    v.get(k).copied().unwrap_or(0.0)
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// Every `phi + 2πm` (m in −4..=4) inside `[lo, hi]` widened by [`ANGLE_SLACK`]. Start angles
/// come from `atan2` and sweeps are at most 2π, so this covers every angle of a sweep.
fn angles_in(lo: f64, hi: f64, phi: f64) -> impl Iterator<Item = f64> {
    (-4..=4)
        .map(move |m| phi + TAU * f64::from(m))
        .filter(move |a| *a >= lo - ANGLE_SLACK && *a <= hi + ANGLE_SLACK)
}

impl Arc {
    /// This arc in the general form of [`SpaceArc`]: a copy of `space` for a mapped arc; for a
    /// plane arc, `u`, `v` are the unit vectors of `a1`, `a2`, the centre has the start point's
    /// coordinates off the plane, `helix` is the motion of the other axes and `miss` the
    /// radius-mismatch correction.
    pub fn to_space(&self) -> SpaceArc {
        if let Some(space) = &self.space {
            return space.clone();
        }
        let n = self.start.len();
        let unit = |axis: usize| {
            let mut e = vec![0.0; n];
            if let Some(x) = e.get_mut(axis) {
                *x = 1.0;
            }
            e
        };
        let mut centre = self.start.clone();
        let mut helix: Vec<f64> = (0..n)
            .map(|i| get(&self.end, i) - get(&self.start, i))
            .collect();
        let mut miss = vec![0.0; n];
        let plane_miss = self.end_miss();
        for (k, axis) in [self.a1, self.a2].into_iter().enumerate() {
            if let Some(c) = centre.get_mut(axis) {
                *c = self.centre[k];
            }
            if let Some(h) = helix.get_mut(axis) {
                *h = 0.0;
            }
            if let Some(m) = miss.get_mut(axis) {
                *m = plane_miss[k];
            }
        }
        SpaceArc {
            centre,
            u: unit(self.a1),
            v: unit(self.a2),
            helix,
            miss,
        }
    }

    fn space_drift(space: &SpaceArc, k: usize) -> f64 {
        get(&space.helix, k) + get(&space.miss, k)
    }

    /// `r · A_k` and `φ_k` of axis `k` (module docs).
    fn space_wave(&self, space: &SpaceArc, k: usize) -> (f64, f64) {
        let (uk, vk) = (get(&space.u, k), get(&space.v, k));
        (self.radius * uk.hypot(vk), vk.atan2(uk))
    }

    pub(super) fn space_length(&self, space: &SpaceArc) -> f64 {
        let turn = self.radius * self.sweep.abs();
        (turn * turn + dot(&space.helix, &space.helix)).sqrt()
    }

    /// The point at fraction `f` of the arc, every entry of `out`.
    pub(super) fn space_point(&self, space: &SpaceArc, f: f64, out: &mut [f64]) {
        let (sin, cos) = (self.start_angle + self.sweep * f).sin_cos();
        for (k, o) in out.iter_mut().enumerate() {
            *o = get(&space.centre, k)
                + self.radius * (get(&space.u, k) * cos + get(&space.v, k) * sin)
                + f * Self::space_drift(space, k);
        }
    }

    /// Exact extent of axis `k` (module docs).
    pub(super) fn space_extent(&self, space: &SpaceArc, k: usize) -> (f64, f64) {
        let (s, e) = (get(&self.start, k), get(&self.end, k));
        let (mut lo, mut hi) = (s.min(e), s.max(e));
        let (amp, phi) = self.space_wave(space, k);
        let drift = Self::space_drift(space, k);
        let q = drift / (amp * self.sweep);
        if q.is_finite() && q.abs() <= 1.0 {
            let (a_lo, a_hi) = self.angle_range();
            let base = q.asin();
            for psi in [base, PI - base] {
                // At θ = φ + ψ + 2πm the wave is amp·cos ψ; f is clamped so that a point found
                // just outside the sweep by rounding is valued (safely) at the end's drift.
                let wave = amp * psi.cos();
                for theta in angles_in(a_lo, a_hi, phi + psi) {
                    let f = ((theta - self.start_angle) / self.sweep).clamp(0.0, 1.0);
                    let value = get(&space.centre, k) + wave + f * drift;
                    lo = lo.min(value);
                    hi = hi.max(value);
                }
            }
        }
        (lo, hi)
    }

    /// Largest `|dp_k / ds|`: `dp_k/df = −amp·sweep·σ + d_k` is monotone in `σ = sin(θ − φ)`,
    /// so its extremes are at the extremes of `σ` over the sweep.
    pub(super) fn space_rate(&self, space: &SpaceArc, k: usize, length: f64) -> f64 {
        let (amp, phi) = self.space_wave(space, k);
        let drift = Self::space_drift(space, k);
        let (a_lo, a_hi) = self.angle_range();
        let ends = [
            (self.start_angle - phi).sin(),
            (self.end_angle() - phi).sin(),
        ];
        let mut s_max = ends[0].max(ends[1]);
        let mut s_min = ends[0].min(ends[1]);
        if angles_in(a_lo, a_hi, phi + FRAC_PI_2).next().is_some() {
            s_max = 1.0;
        }
        if angles_in(a_lo, a_hi, phi - FRAC_PI_2).next().is_some() {
            s_min = -1.0;
        }
        let g = |s: f64| (drift - amp * self.sweep * s).abs();
        let rate = g(s_min).max(g(s_max)) / length;
        if space.miss.iter().all(|m| *m == 0.0) {
            rate.min(1.0)
        } else {
            rate
        }
    }
}

fn mapped_point(map: &dyn AffineMap, p: &[f64]) -> Vec<f64> {
    let mut out = vec![f64::NAN; p.len()];
    map.map_point(p, &mut out);
    out
}

fn mapped_vector(map: &dyn AffineMap, d: &[f64]) -> Vec<f64> {
    let mut out = vec![f64::NAN; d.len()];
    map.map_vector(d, &mut out);
    out
}

fn rigid(ok: bool, what: &'static str) -> Result<(), PathError> {
    if ok {
        Ok(())
    } else {
        Err(PathError::NotRigid { what })
    }
}

impl Segment {
    /// This segment mapped through the rigid map `map` (a rotation plus a translation, such as
    /// [`Frames::pcs_to_acs_map`](crate::core::frames::Frames::pcs_to_acs_map) under `#CS`,
    /// FCT-C4 §4): a line becomes the line between the mapped end points, an arc becomes an
    /// arc whose [`Arc::space`] holds the mapped circle (see the [`space`](self) docs). The path
    /// coordinate is kept: `transformed.point_at(s)` is `map(self.point_at(s))`, up to rounding.
    /// Radius, start angle and sweep are kept; `a1`, `a2` and `centre` keep describing the
    /// plane arc the geometry came from.
    ///
    /// Errors: a mapped value that is not finite or is out of range, and
    /// [`PathError::NotRigid`] when the map does not keep lengths and right angles (within
    /// 1e-9) or `map_point` and `map_vector` disagree.
    pub fn transformed(&self, map: &dyn AffineMap) -> Result<Segment, PathError> {
        let arc = match self {
            Segment::Line(l) => {
                return Segment::line(mapped_point(map, &l.start), mapped_point(map, &l.end));
            }
            Segment::Arc(arc) => arc,
        };
        let space = arc.to_space();
        let start = mapped_point(map, &arc.start);
        let end = mapped_point(map, &arc.end);
        check_dims(&start, &end)?;
        check_values(&start, "start point")?;
        check_values(&end, "end point")?;
        let centre = mapped_point(map, &space.centre);
        let mut u = mapped_vector(map, &space.u);
        let mut v = mapped_vector(map, &space.v);
        let helix = mapped_vector(map, &space.helix);
        let miss = mapped_vector(map, &space.miss);
        for (values, what) in [
            (&centre, "mapped centre"),
            (&u, "mapped u"),
            (&v, "mapped v"),
            (&helix, "mapped helix"),
            (&miss, "mapped miss"),
        ] {
            check_values(values, what)?;
        }
        let (nu, nv) = (norm(&u), norm(&v));
        rigid(
            (nu - 1.0).abs() <= RIGID_TOLERANCE,
            "u is not a unit vector",
        )?;
        rigid(
            (nv - 1.0).abs() <= RIGID_TOLERANCE,
            "v is not a unit vector",
        )?;
        rigid(dot(&u, &v).abs() <= RIGID_TOLERANCE, "u, v not orthogonal")?;
        let hn = norm(&space.helix);
        let h_scale = RIGID_TOLERANCE * hn.max(1.0);
        rigid((norm(&helix) - hn).abs() <= h_scale, "helix length changed")?;
        rigid(
            dot(&helix, &u).abs() <= h_scale && dot(&helix, &v).abs() <= h_scale,
            "helix not orthogonal to the plane",
        )?;
        let mn = norm(&space.miss);
        rigid(
            (norm(&miss) - mn).abs() <= RIGID_TOLERANCE * mn.max(1.0),
            "miss length changed",
        )?;
        // Gram–Schmidt removes the last rounding from the basis.
        u.iter_mut().for_each(|x| *x /= nu);
        let uv = dot(&u, &v);
        v.iter_mut().zip(&u).for_each(|(x, y)| *x -= uv * y);
        let nv = norm(&v);
        v.iter_mut().for_each(|x| *x /= nv);
        let mapped = Arc {
            start,
            end,
            a1: arc.a1,
            a2: arc.a2,
            centre: arc.centre,
            radius: arc.radius,
            start_angle: arc.start_angle,
            sweep: arc.sweep,
            space: Some(SpaceArc {
                centre,
                u,
                v,
                helix,
                miss,
            }),
        };
        // map_point and map_vector must be the same affine map: the mapped start point must be
        // the start of the mapped circle.
        let mut at_start = vec![0.0; mapped.start.len()];
        if let Some(space) = &mapped.space {
            mapped.space_point(space, 0.0, &mut at_start);
        }
        let scale = norm(&mapped.start).max(arc.radius).max(1.0);
        let gap = at_start
            .iter()
            .zip(&mapped.start)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        rigid(
            gap <= RIGID_TOLERANCE * scale,
            "point and vector maps disagree",
        )?;
        Ok(Segment::Arc(mapped))
    }
}
