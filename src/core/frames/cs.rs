//! `#CS ON[x, y, z, a, b, c]`: the Cartesian machining coordinate system (FCT-C4 §4, §5 meas3,
//! meas4), as an [`Isometry3`].
//!
//! # Convention
//!
//! `#CS ON[x, y, z, a, b, c]` maps a point `w` of the CS frame to the ACS as
//! `acs = (x, y, z) + R · w` with `R = R_z(c) · R_y(b) · R_x(a)`, angles in degrees, each `R_*`
//! the standard right-handed rotation about the ACS axis (`R_y(b)`: `x' = x·cos b + z·sin b`,
//! `z' = −x·sin b + z·cos b`).
//!
//! FCT-C4 §5 meas4 fixes the single-rotation case: with `#CS ON[0,0,75,0,15,0]` the CS point
//! `w = (150, 0, 20)` is at ACS `z = 75 − 150·sin 15° + 20·cos 15° ≈ 55.5`, the probing position
//! of the example. The order of several rotations (`R_z · R_y · R_x`: first about X, then Y,
//! then Z, all about the fixed ACS axes) is an interpretation: the seed shows only single
//! rotations (§4: `#CS ON[0,0,0,0,45]`, `#CS ON[0,0,0,0,0,90]`; §5 meas4).
//!
//! Fewer than six values are padded with zeros (`#CS ON[0,0,0,0,45]` is a 45° rotation about Y,
//! as in §4's example).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use super::{check_value, FrameError};

/// A `#CS` transformation: the rigid map from the CS frame (`w`) to the ACS on the three main
/// axes X, Y, Z. See the module docs for the convention.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CsTransform {
    iso: Isometry3<f64>,
    values: [f64; 6],
}

impl Default for CsTransform {
    fn default() -> Self {
        Self::identity()
    }
}

impl CsTransform {
    /// Most values `#CS ON[...]` takes: `x, y, z, a, b, c`.
    pub const MAX_VALUES: usize = 6;

    /// The identity (`#CS ON[0,0,0,0,0,0]`).
    pub fn identity() -> Self {
        CsTransform {
            iso: Isometry3::identity(),
            values: [0.0; 6],
        }
    }

    /// From the values of `#CS ON[x, y, z, a, b, c]`: offsets in mm, angles in degrees; missing
    /// trailing values are 0 (FCT-C4 §4).
    ///
    /// Errors: more than six values, a value that is not finite or beyond
    /// ±[`MAX_COORDINATE`](crate::core::path::MAX_COORDINATE).
    pub fn from_cs_on(values: &[f64]) -> Result<Self, FrameError> {
        if values.len() > Self::MAX_VALUES {
            return Err(FrameError::CsArity { got: values.len() });
        }
        let mut v = [0.0; 6];
        for (slot, &value) in v.iter_mut().zip(values) {
            *slot = check_value(value, "#CS value")?;
        }
        // `%` is exact, so 360° is exactly no turn and huge angles keep their precision.
        let rad = |deg: f64| (deg % 360.0).to_radians();
        let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rad(v[5]))
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), rad(v[4]))
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), rad(v[3]));
        let iso = Isometry3::from_parts(Translation3::new(v[0], v[1], v[2]), rotation);
        Ok(CsTransform { iso, values: v })
    }

    /// The six values it was made from (`x, y, z` in mm, `a, b, c` in degrees).
    pub fn values(&self) -> [f64; 6] {
        self.values
    }

    /// The isometry `w → ACS`.
    pub fn isometry(&self) -> &Isometry3<f64> {
        &self.iso
    }

    /// The rotation `R` as a row-major matrix: `acs = translation + R · w`.
    pub fn rotation_matrix(&self) -> [[f64; 3]; 3] {
        let m = self.iso.rotation.to_rotation_matrix();
        let m = m.matrix();
        [
            [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
            [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
            [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
        ]
    }

    /// The offset `(x, y, z)`: the ACS position of the CS origin.
    pub fn translation(&self) -> [f64; 3] {
        let t = self.iso.translation.vector;
        [t.x, t.y, t.z]
    }

    /// CS frame point → ACS point (`offset + R · w`).
    pub fn to_acs(&self, w: [f64; 3]) -> [f64; 3] {
        let p = self.iso.transform_point(&Point3::new(w[0], w[1], w[2]));
        [p.x, p.y, p.z]
    }

    /// ACS point → CS frame point (`Rᵀ · (acs − offset)`).
    pub fn to_cs(&self, acs: [f64; 3]) -> [f64; 3] {
        let p = self
            .iso
            .inverse_transform_point(&Point3::new(acs[0], acs[1], acs[2]));
        [p.x, p.y, p.z]
    }

    /// CS frame direction → ACS direction (`R · d`, no offset).
    pub fn apply_dir(&self, d: [f64; 3]) -> [f64; 3] {
        let v = self.iso.rotation * Vector3::new(d[0], d[1], d[2]);
        [v.x, v.y, v.z]
    }

    /// ACS direction → CS frame direction (`Rᵀ · d`).
    pub fn inverse_dir(&self, d: [f64; 3]) -> [f64; 3] {
        let v = self
            .iso
            .rotation
            .inverse_transform_vector(&Vector3::new(d[0], d[1], d[2]));
        [v.x, v.y, v.z]
    }

    /// No offset and no rotation.
    pub fn is_identity(&self) -> bool {
        !self.has_rotation() && self.translation() == [0.0; 3]
    }

    /// Whether the rotation is not exactly the identity (all angles multiples of 360° are none).
    pub fn has_rotation(&self) -> bool {
        self.iso.rotation != UnitQuaternion::identity()
    }
}
