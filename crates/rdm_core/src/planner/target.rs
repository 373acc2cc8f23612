//! End-effector task rows of eq. (56): J_ee δζ ≈ δξ_ee with the step of eq. (54), for the
//! three orientation kinds a target can have.
//!
//! * [`EeOrientation::Free`]: 3 rows, the position (rotation rows weighted 0);
//! * [`EeOrientation::Pose`]: 6 rows, position and the rotation vector of R_d R_eeᵀ;
//! * [`EeOrientation::Axis`]: 5 rows, the position and the tool axis a (the end-effector
//!   frame's x axis, the tool flange's axis; ASSUMPTION: the paper's ξ_ee is a full pose and
//!   it names no axis-only task) turned toward a world direction a_d with the rotation about
//!   a left free. a changes as δa = δω × a, so only δω's components across a move it: with
//!   b1, b2 a unit basis of the plane normal to a, the rows are
//!   `[b1ᵀ J_ω; b2ᵀ J_ω] δζ ≈ [b1ᵀ δr; b2ᵀ δr]` where J_ω are eq. (53)'s rotation rows and
//!   δr is eq. (54)'s step applied to the rotation vector r = ∠(a, a_d) (a × a_d)/|a × a_d|
//!   (the shortest turn of a onto a_d, normal to a). Their weight is S2''s orientation
//!   weight. The cost is the same for any b1, b2 (b1 b1ᵀ + b2 b2ᵀ = I - a aᵀ).

use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use super::config::PlannerConfig;
use crate::model::Matrix6xN;

/// What the end effector's orientation must reach.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EeOrientation {
    /// Position only (3-D task).
    Free,
    /// Full orientation (6-D task), world frame.
    Pose(UnitQuaternion<f64>),
    /// Tool axis (end-effector x axis) along this world direction, rotation about it free
    /// (5-D task). Need not be unit length; must not be zero.
    Axis(Vector3<f64>),
}

/// Errors before the step of eq. (54): `(position, orientation)`, [m] and [rad].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TaskErrors {
    pub position: f64,
    pub orientation: f64,
}

/// A unit vector normal to unit `a` (the world axis least aligned with `a`, crossed).
fn normal_to(a: &Vector3<f64>) -> Vector3<f64> {
    let i = a.iamin();
    let mut e = Vector3::zeros();
    e[i] = 1.0;
    a.cross(&e).normalize()
}

/// The end-effector task of one step: `rows` (6 x n_zeta, row r multiplies δζ), `step`
/// (δξ of eq. 54) and `weights` (the diagonal of S2'; 0 for rows the target leaves free).
#[derive(Clone, Debug)]
pub struct TaskRows {
    pub rows: Matrix6xN,
    pub step: [f64; 6],
    pub weights: [f64; 6],
}

impl TaskRows {
    /// Rows for a state of `n_zeta` entries (allocates once).
    pub fn new(n_zeta: usize) -> Self {
        Self {
            rows: Matrix6xN::zeros(n_zeta),
            step: [0.0; 6],
            weights: [0.0; 6],
        }
    }

    /// Fill the rows from the end-effector pose and Jacobian `j_ee` (allocates nothing).
    /// Axis: its direction must be finite and non-zero (checked by the caller).
    pub fn fill(
        &mut self,
        cfg: &PlannerConfig,
        ee_pose: &Isometry3<f64>,
        j_ee: &Matrix6xN,
        position: &Vector3<f64>,
        orientation: &EeOrientation,
    ) -> TaskErrors {
        let rows = &mut self.rows;
        rows.copy_from(j_ee);
        let e_pos = position - ee_pose.translation.vector;
        let pos_err = e_pos.norm();
        let d_pos = e_pos * (cfg.kappa_position / pos_err.max(1e-12)).min(1.0);
        let w_ori = cfg.s2_ee_orientation;
        let (rot, w) = match orientation {
            EeOrientation::Free => (Vector3::zeros(), [0.0; 3]),
            EeOrientation::Pose(r) => ((r * ee_pose.rotation.inverse()).scaled_axis(), [w_ori; 3]),
            EeOrientation::Axis(a_d) => {
                let a = ee_pose.rotation * Vector3::x();
                let a_d = a_d.normalize();
                let cross = a.cross(&a_d);
                let angle = cross.norm().atan2(a.dot(&a_d));
                let b1 = normal_to(&a);
                let b2 = a.cross(&b1);
                let rot = if cross.norm() > 1e-12 {
                    cross * (angle / cross.norm())
                } else if angle > 1.0 {
                    b1 * angle // a = -a_d: any turn across a
                } else {
                    Vector3::zeros()
                };
                for c in 0..rows.ncols() {
                    let w_col = Vector3::new(j_ee[(3, c)], j_ee[(4, c)], j_ee[(5, c)]);
                    rows[(3, c)] = b1.dot(&w_col);
                    rows[(4, c)] = b2.dot(&w_col);
                    rows[(5, c)] = 0.0;
                }
                (
                    Vector3::new(b1.dot(&rot), b2.dot(&rot), 0.0),
                    [w_ori, w_ori, 0.0],
                )
            }
        };
        let rot_err = rot.norm();
        let d_rot = rot * (cfg.kappa_orientation / rot_err.max(1e-12)).min(1.0);
        for r in 0..3 {
            self.step[r] = d_pos[r];
            self.weights[r] = cfg.s2_ee_position;
            self.step[3 + r] = d_rot[r];
            self.weights[3 + r] = w[r];
        }
        TaskErrors {
            position: pos_err,
            orientation: rot_err,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// End effector at the identity (tool axis = world x), J_ee = I (6 x 6: δξ = δζ).
    fn rows_toward(orientation: EeOrientation) -> (TaskRows, TaskErrors) {
        let cfg = PlannerConfig::new(super::super::config::Mode::Perched);
        let cfg = PlannerConfig {
            s2_ee_orientation: 0.1,
            ..cfg
        };
        let mut j = Matrix6xN::zeros(6);
        j.fill_with_identity();
        let mut t = TaskRows::new(6);
        let e = t.fill(
            &cfg,
            &Isometry3::identity(),
            &j,
            &Vector3::new(0.0, 0.0, 0.0),
            &orientation,
        );
        (t, e)
    }

    #[test]
    fn axis_rows_turn_the_tool_axis_toward_the_target_about_a_normal() {
        let (t, e) = rows_toward(EeOrientation::Axis(Vector3::new(0.0, 0.0, 2.0)));
        assert!((e.orientation - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert_eq!(t.weights[3..], [0.1, 0.1, 0.0]);
        // rotation rate of the least-squares step: rows 3-4 are orthonormal here
        let mut w: Vector3<f64> = Vector3::zeros();
        for r in 3..5 {
            for c in 0..3 {
                w[c] += t.rows[(r, 3 + c)] * t.step[r];
            }
            // each row is normal to the axis: a rotation about the axis does not move it
            assert!(t.rows[(r, 3)].abs() < 1e-15);
        }
        let a = Vector3::x() + w.cross(&Vector3::x());
        assert!((w.norm() - 0.03).abs() < 1e-12); // kappa_orientation
        assert!((a.z - 0.03).abs() < 1e-12 && a.y.abs() < 1e-15);
    }

    #[test]
    fn a_reached_axis_and_a_free_orientation_ask_for_no_rotation() {
        let (t, e) = rows_toward(EeOrientation::Axis(Vector3::new(3.0, 0.0, 0.0)));
        assert_eq!(e.orientation, 0.0);
        assert_eq!(t.step[3..], [0.0; 3]);
        let (t, _) = rows_toward(EeOrientation::Free);
        assert_eq!(t.weights[3..], [0.0; 3]);
    }
}
