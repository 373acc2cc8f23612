//! The contact plane of the perching QP: eqs. (39)-(44) are written for a ceiling (the
//! surface normal along the foot's −z); [`ContactPlane`] carries them to any plane.
//!
//! The plane is given in foot axes by its outward unit normal `n` (from the surface towards
//! the robot; the ceiling's is `(0, 0, −1)`) and the centre `c` of the footplate's contact
//! face (the ceiling face: the foot origin, `(0, 0, 0)`). Its frame `P` has origin `c` and
//! axes `t₁, t₂, d = −n` (`d`: the direction the foot presses in, so `F_n = d·F > 0` presses,
//! eq. 39). The tangents are the images of the foot's `x, y` under the smallest rotation
//! taking `z` to `d` (Rodrigues: axis `z × d`, angle `acos(z·d)`); for `d = −z` (a floor),
//! where that axis is undefined, the rotation of π about `x` (`t₁ = x`, `t₂ = −y`).
//! The ceiling is exactly the identity with `c = 0`: wrenches and allocation rows pass
//! unchanged (no arithmetic), so the QP's answer for the ceiling is bit-for-bit the one of the
//! foot-frame formulation.
//!
//! In plane coordinates the QP's wrench is `[F_t1, F_t2, F_n, M_t1, M_t2, M_n]` about `c`:
//! eq. (40) bounds `|F_t1| ≤ μ_x F_n`, `|F_t2| ≤ μ_y F_n`, eq. (41) `|M_n| ≤ μ_z F_n`,
//! eqs. (42)-(44) the ZMP `(p_t1, p_t2)` within `(H_x, H_y)` of `c`.

use nalgebra::{Matrix3, Matrix4, Matrix6x4, Vector3};

use super::error::ParamError;
use crate::PERCH_ROTORS;

/// The ceiling's outward normal in foot axes (the plane of the paper's eqs. 39-44).
pub const CEILING_NORMAL: [f64; 3] = [0.0, 0.0, -1.0];
/// How far from 1 the norm of a given normal may be.
const UNIT_TOL: f64 = 1e-6;

/// A contact plane in foot axes: the rotation to its frame and its centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactPlane {
    /// Columns `t₁, t₂, d` in foot axes.
    rotation: Matrix3<f64>,
    /// Centre of the contact face in the foot frame [m].
    center: Vector3<f64>,
    /// The ceiling at the foot origin: every transform is the identity.
    foot_frame: bool,
}

impl Default for ContactPlane {
    fn default() -> Self {
        Self {
            rotation: Matrix3::identity(),
            center: Vector3::zeros(),
            foot_frame: true,
        }
    }
}

impl ContactPlane {
    /// The plane with outward unit normal `normal` and face centre `center` (foot frame).
    /// Errors name `contact_normal` (not finite, or norm not 1 within 1e-6) or
    /// `contact_center` (not finite).
    pub fn new(normal: [f64; 3], center: [f64; 3]) -> Result<Self, ParamError> {
        let n = Vector3::from(normal);
        if !n.iter().all(|v| v.is_finite()) || (n.norm() - 1.0).abs() > UNIT_TOL {
            return Err(ParamError {
                field: "contact_normal",
                reason: "must be a finite unit vector (norm 1 within 1e-6)",
            });
        }
        if !center.iter().all(|v| v.is_finite()) {
            return Err(ParamError {
                field: "contact_center",
                reason: "must be finite",
            });
        }
        let center = Vector3::from(center);
        if normal == CEILING_NORMAL && center == Vector3::zeros() {
            return Ok(Self::default());
        }
        let d = -n / n.norm();
        let z = Vector3::z();
        let c = z.dot(&d);
        let rotation = if c <= -1.0 + 1e-12 {
            // d = −z: rotation by π about x
            Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0))
        } else {
            // Rodrigues with k = z × d (|k| = sin θ): R = I + [k]× + [k]×² / (1 + c)
            let k = z.cross(&d);
            let kx = k.cross_matrix();
            Matrix3::identity() + kx + kx * kx / (1.0 + c)
        };
        Ok(Self {
            rotation,
            center,
            foot_frame: false,
        })
    }

    /// True for the ceiling at the foot origin (the transforms are the identity).
    pub fn is_foot_frame(&self) -> bool {
        self.foot_frame
    }

    /// Columns `t₁, t₂, d` of the plane's axes in foot axes.
    pub fn rotation(&self) -> Matrix3<f64> {
        self.rotation
    }

    /// Centre of the contact face in the foot frame [m].
    pub fn center(&self) -> [f64; 3] {
        self.center.into()
    }

    /// A wrench `[F, M]` in foot axes about the foot origin, in plane axes about the centre:
    /// `[Rᵀ F, Rᵀ (M − c × F)]`.
    pub fn wrench(&self, foot: &[f64; 6]) -> [f64; 6] {
        if self.foot_frame {
            return *foot;
        }
        let f = Vector3::new(foot[0], foot[1], foot[2]);
        let m = Vector3::new(foot[3], foot[4], foot[5]) - self.center.cross(&f);
        let rt = self.rotation.transpose();
        let (fp, mp) = (rt * f, rt * m);
        [fp[0], fp[1], fp[2], mp[0], mp[1], mp[2]]
    }

    /// The QP's allocation rows `[F_n, M_t1, M_t2, M_n]` (plane axes, about the centre) from
    /// the six rows `[F_x, F_y, F_z, M_x, M_y, M_z]` of the wrench unit rotor thrusts produce
    /// about the foot origin in foot axes (columns = rotors).
    pub fn allocation(&self, foot: &Matrix6x4<f64>) -> Matrix4<f64> {
        let mut out = Matrix4::zeros();
        for col in 0..PERCH_ROTORS {
            let column = foot.column(col);
            let w = self.wrench(&[
                column[0], column[1], column[2], column[3], column[4], column[5],
            ]);
            out[(0, col)] = w[2];
            out[(1, col)] = w[3];
            out[(2, col)] = w[4];
            out[(3, col)] = w[5];
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ceiling_is_the_identity_bit_for_bit() {
        let p = ContactPlane::new(CEILING_NORMAL, [0.0; 3]).unwrap();
        assert!(p.is_foot_frame());
        let w = [0.1, -0.2, 3.0, 1e-17, -0.0, 7.5];
        assert_eq!(p.wrench(&w).map(f64::to_bits), w.map(f64::to_bits));
    }

    #[test]
    fn a_wall_in_front_presses_along_x_with_tangents_down_and_y() {
        // outward normal −x: the foot presses along +x; t₁ = −z (down), t₂ = y
        let p = ContactPlane::new([-1.0, 0.0, 0.0], [0.05, 0.0, -0.03]).unwrap();
        let r = p.rotation();
        let close = |a: Vector3<f64>, b: [f64; 3]| (a - Vector3::from(b)).norm() < 1e-15;
        assert!(close(r.column(0).into(), [0.0, 0.0, -1.0]));
        assert!(close(r.column(1).into(), [0.0, 1.0, 0.0]));
        assert!(close(r.column(2).into(), [1.0, 0.0, 0.0]));
        // 10 N pressing at the face centre, 2 N of weight carried (foot pushed down −z: F_t1
        // = +2), no moment about the centre
        let c = Vector3::new(0.05, 0.0, -0.03);
        let f = Vector3::new(10.0, 0.0, -2.0);
        let m = c.cross(&f);
        let w = p.wrench(&[f[0], f[1], f[2], m[0], m[1], m[2]]);
        let want = [2.0, 0.0, 10.0, 0.0, 0.0, 0.0];
        for (a, b) in w.iter().zip(want.iter()) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
    }

    #[test]
    fn a_floor_and_bad_normals() {
        let p = ContactPlane::new([0.0, 0.0, 1.0], [0.0; 3]).unwrap();
        assert_eq!(
            p.rotation(),
            Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0))
        );
        let e = ContactPlane::new([0.0, 0.0, -2.0], [0.0; 3]).unwrap_err();
        assert_eq!(e.field, "contact_normal");
        let e = ContactPlane::new([f64::NAN, 0.0, -1.0], [0.0; 3]).unwrap_err();
        assert_eq!(e.field, "contact_normal");
        let e = ContactPlane::new(CEILING_NORMAL, [0.0, f64::INFINITY, 0.0]).unwrap_err();
        assert_eq!(e.field, "contact_center");
    }
}
