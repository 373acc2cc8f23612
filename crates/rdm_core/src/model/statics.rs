//! Static joint torques of eq. (61):
//! `tau = -J'_rotor^T W_rotor - sum J'_contact^T W_contact - sum J'_part^T m_part g`,
//! with J' the joint columns of each point's Jacobian relative to the root link (the
//! foot). Quasi-static: q-dot, q-ddot and xi-ddot are zero.

use nalgebra::{Vector3, Vector6};

use super::description::RobotDescription;
use super::error::{check_input, ModelError};
use super::workspace::ModelWorkspace;

/// External loads of a static-torque query. Wrenches are applied TO the robot, expressed
/// in world axes, force `[fx, fy, fz]` then moment `[mx, my, mz]` about the frame origin.
#[derive(Clone, Copy, Debug)]
pub struct StaticLoads<'a> {
    /// Rotor thrusts lambda_i [N] (rotor order).
    pub thrusts: &'a [f64],
    /// Wrench on the foot at the foot frame origin.
    pub foot_wrench: &'a [f64; 6],
    /// Wrench on the end effector at its frame origin.
    pub end_effector_wrench: &'a [f64; 6],
    /// Gravity acceleration vector g (world), e.g. [0, 0, -9.80665].
    pub gravity: &'a [f64; 3],
}

impl RobotDescription {
    /// Joint torques (q order) the servos must exert to hold the configuration, into `tau`.
    /// Returns the net external wrench on the whole robot about the base origin (world
    /// axes): zero when the loads are in equilibrium; otherwise the base must supply it.
    pub fn static_torques(
        &self,
        ws: &ModelWorkspace,
        loads: &StaticLoads<'_>,
        tau: &mut [f64],
    ) -> Result<Vector6<f64>, ModelError> {
        if !ws.evaluated {
            return Err(ModelError::NotEvaluated);
        }
        if tau.len() != self.n_q() {
            return Err(ModelError::WrongLength {
                what: "tau",
                expected: self.n_q(),
                got: tau.len(),
            });
        }
        check_input("thrusts", loads.thrusts, self.n_rotors())?;
        check_input("foot_wrench", loads.foot_wrench, 6)?;
        check_input("end_effector_wrench", loads.end_effector_wrench, 6)?;
        check_input("gravity", loads.gravity, 3)?;
        tau.fill(0.0);
        let base = ws.base.translation.vector;
        let mut residual = Vector6::zeros();
        let mut apply =
            |link: usize, point: Vector3<f64>, force: Vector3<f64>, moment: Vector3<f64>| {
                for &qi in &self.ancestors[link] {
                    let lever = point - ws.joint_point[qi];
                    tau[qi] -= ws.joint_axis[qi].dot(&(lever.cross(&force) + moment));
                }
                let total_moment = (point - base).cross(&force) + moment;
                let mut top = residual.fixed_rows_mut::<3>(0);
                top += force;
                let mut bottom = residual.fixed_rows_mut::<3>(3);
                bottom += total_moment;
            };
        let g = Vector3::from(*loads.gravity);
        for (l, link) in self.links.iter().enumerate() {
            if link.mass > 0.0 {
                let com = ws.link_pose[l].transform_point(&link.com.into()).coords;
                apply(l, com, link.mass * g, Vector3::zeros());
            }
        }
        for (i, rotor) in self.rotors.iter().enumerate() {
            let thrust = loads.thrusts[i] * ws.rotor_direction[i];
            let drag = -rotor.drag_to_thrust * rotor.spin * thrust;
            apply(rotor.link, ws.rotor_position[i], thrust, drag);
        }
        let wrench = |w: &[f64; 6]| {
            (
                Vector3::new(w[0], w[1], w[2]),
                Vector3::new(w[3], w[4], w[5]),
            )
        };
        let (f, m) = wrench(loads.foot_wrench);
        apply(
            self.foot_link,
            ws.link_pose[self.foot_link].translation.vector,
            f,
            m,
        );
        let (f, m) = wrench(loads.end_effector_wrench);
        let ee = self.end_effector_link;
        apply(ee, ws.link_pose[ee].translation.vector, f, m);
        Ok(residual)
    }
}
