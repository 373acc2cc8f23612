//! Jacobians w.r.t. zeta = [p, eta, q] (eq. 53): p the base position, eta its ZYX Euler
//! angles (roll, pitch, yaw), q the joint vector. Rows: world-frame linear velocity of the
//! frame origin, then world-frame angular velocity (a small rotation vector, not Euler
//! angle increments). Columns: 6 + n_q.

use nalgebra::{Rotation3, Vector3};

use super::description::RobotDescription;
use super::error::ModelError;
use super::kinematics::Frame;
use super::workspace::{Matrix6xN, ModelWorkspace};

impl RobotDescription {
    /// Angular velocities produced by unit rates of roll, pitch and yaw of the base.
    fn euler_columns(ws: &ModelWorkspace) -> [Vector3<f64>; 3] {
        let (_roll, pitch, yaw) = ws.base.rotation.euler_angles();
        let rz = Rotation3::from_euler_angles(0.0, 0.0, yaw);
        let ry = Rotation3::from_euler_angles(0.0, pitch, 0.0);
        [rz * ry * Vector3::x(), rz * Vector3::y(), Vector3::z()]
    }

    /// Jacobian of `frame` into `out` (6 x (6 + n_q), caller-owned).
    pub fn frame_jacobian(
        &self,
        ws: &ModelWorkspace,
        frame: Frame,
        out: &mut Matrix6xN,
    ) -> Result<(), ModelError> {
        if !ws.evaluated {
            return Err(ModelError::NotEvaluated);
        }
        let n_cols = 6 + self.n_q();
        if out.ncols() != n_cols {
            return Err(ModelError::WrongLength {
                what: "jacobian columns",
                expected: n_cols,
                got: out.ncols(),
            });
        }
        out.fill(0.0);
        if frame == Frame::World {
            return Ok(());
        }
        let (point, link) = self.frame_point(ws, frame)?;
        let base = ws.base.translation.vector;
        for k in 0..3 {
            out[(k, k)] = 1.0;
        }
        for (k, w) in Self::euler_columns(ws).iter().enumerate() {
            let mut col = out.column_mut(3 + k);
            col.fixed_rows_mut::<3>(0)
                .copy_from(&w.cross(&(point - base)));
            col.fixed_rows_mut::<3>(3).copy_from(w);
        }
        match link {
            Some(l) => {
                for &qi in &self.ancestors[l] {
                    let a = ws.joint_axis[qi];
                    let mut col = out.column_mut(6 + qi);
                    col.fixed_rows_mut::<3>(0)
                        .copy_from(&a.cross(&(point - ws.joint_point[qi])));
                    col.fixed_rows_mut::<3>(3).copy_from(&a);
                }
            }
            None => self.cog_joint_columns(ws, out),
        }
        Ok(())
    }

    /// Joint columns of the CoG: mass-weighted link CoM Jacobians; angular rows: the CoG
    /// frame turns with the foot frame.
    fn cog_joint_columns(&self, ws: &ModelWorkspace, out: &mut Matrix6xN) {
        if ws.mass <= 0.0 {
            return;
        }
        for (l, link) in self.links.iter().enumerate() {
            if link.mass <= 0.0 {
                continue;
            }
            let com = ws.link_pose[l].transform_point(&link.com.into()).coords;
            let share = link.mass / ws.mass;
            for &qi in &self.ancestors[l] {
                let v = ws.joint_axis[qi].cross(&(com - ws.joint_point[qi])) * share;
                let mut col = out.column_mut(6 + qi);
                let mut top = col.fixed_rows_mut::<3>(0);
                top += v;
            }
        }
        for &qi in &self.ancestors[self.foot_link] {
            out.column_mut(6 + qi)
                .fixed_rows_mut::<3>(3)
                .copy_from(&ws.joint_axis[qi]);
        }
    }
}
