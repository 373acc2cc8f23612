//! Forward kinematics of every frame, and the single `evaluate` entry point that fills a
//! workspace with kinematics, mass properties and the allocation matrix.

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::description::RobotDescription;
use super::error::{check_finite, check_input, ModelError};
use super::workspace::ModelWorkspace;

/// A frame of the robot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame {
    /// The world frame W.
    World,
    /// The CoG frame C: at the centre of mass, axes of the foot frame.
    Cog,
    /// A link frame (index into `RobotDescription::links`); named frames map to links.
    Link(usize),
    /// A rotor frame: at the rotor, axes of its parent link.
    Rotor(usize),
}

/// Base pose from zeta's first six entries: position p and ZYX Euler angles
/// eta = (roll, pitch, yaw), R = Rz(yaw) Ry(pitch) Rx(roll).
pub fn base_pose_from_zeta(p: &Vector3<f64>, eta: &Vector3<f64>) -> Isometry3<f64> {
    let r = Rotation3::from_euler_angles(eta.x, eta.y, eta.z);
    Isometry3::from_parts(
        Translation3::from(*p),
        UnitQuaternion::from_rotation_matrix(&r),
    )
}

impl RobotDescription {
    /// Resolve a frame name: `world`, `cog`, a `[frames]` name (`foot`, `end_effector`),
    /// a URDF link name or a rotor name.
    pub fn frame(&self, name: &str) -> Result<Frame, ModelError> {
        match name {
            "world" => return Ok(Frame::World),
            "cog" => return Ok(Frame::Cog),
            _ => {}
        }
        if let Some(&(_, l)) = self.named_frames.iter().find(|(n, _)| n == name) {
            return Ok(Frame::Link(l));
        }
        if let Some(l) = self.links.iter().position(|l| l.name == name) {
            return Ok(Frame::Link(l));
        }
        if let Some(r) = self.rotors.iter().position(|r| r.name == name) {
            return Ok(Frame::Rotor(r));
        }
        Err(ModelError::UnknownFrame(name.to_owned()))
    }

    /// Evaluate kinematics, mass properties and Q(q) for `q` (joint order of the TOML) and
    /// the base (root link) pose. Allocation-free; on error the workspace is marked stale.
    pub fn evaluate(
        &self,
        q: &[f64],
        base: &Isometry3<f64>,
        ws: &mut ModelWorkspace,
    ) -> Result<(), ModelError> {
        ws.evaluated = false;
        if !ws.fits(self) {
            return Err(ModelError::WorkspaceMismatch);
        }
        check_input("q", q, self.n_q())?;
        let t = base.translation.vector;
        let r = base.rotation.coords;
        check_finite("base_pose", &[t.x, t.y, t.z, r.x, r.y, r.z, r.w])?;
        ws.q.copy_from_slice(q);
        ws.base = *base;
        self.forward_kinematics(ws);
        self.fill_mass_properties(ws);
        self.fill_allocation(ws);
        ws.evaluated = true;
        Ok(())
    }

    fn forward_kinematics(&self, ws: &mut ModelWorkspace) {
        ws.link_pose[self.root_link] = ws.base;
        for joint in &self.joints {
            let mount = ws.link_pose[joint.parent_link] * joint.origin;
            let pose = match (joint.axis, joint.q_index) {
                (Some(axis), Some(qi)) => {
                    ws.joint_axis[qi] = mount.rotation * axis;
                    ws.joint_point[qi] = mount.translation.vector;
                    let motion = UnitQuaternion::from_scaled_axis(axis * ws.q[qi]);
                    mount * motion
                }
                _ => mount,
            };
            ws.link_pose[joint.child_link] = pose;
        }
        for (i, rotor) in self.rotors.iter().enumerate() {
            let link = &ws.link_pose[rotor.link];
            ws.rotor_position[i] = link.transform_point(&rotor.offset.into()).coords;
            ws.rotor_direction[i] = link.rotation * rotor.axis;
        }
        ws.cog_rotation = ws.link_pose[self.foot_link].rotation;
    }

    /// World pose of a frame (needs a successful `evaluate`).
    pub fn frame_pose(
        &self,
        ws: &ModelWorkspace,
        frame: Frame,
    ) -> Result<Isometry3<f64>, ModelError> {
        if !ws.evaluated {
            return Err(ModelError::NotEvaluated);
        }
        match frame {
            Frame::World => Ok(Isometry3::identity()),
            Frame::Cog => Ok(ws.cog_pose()),
            Frame::Link(l) => ws
                .link_pose
                .get(l)
                .copied()
                .ok_or_else(|| ModelError::UnknownFrame(format!("link #{l}"))),
            Frame::Rotor(r) => {
                let rotor = self
                    .rotors
                    .get(r)
                    .ok_or_else(|| ModelError::UnknownFrame(format!("rotor #{r}")))?;
                let link = ws.link_pose[rotor.link];
                Ok(Isometry3::from_parts(
                    ws.rotor_position[r].into(),
                    link.rotation,
                ))
            }
        }
    }

    /// World position of a frame's origin and the link it moves with (`None`: world).
    pub(crate) fn frame_point(
        &self,
        ws: &ModelWorkspace,
        frame: Frame,
    ) -> Result<(Vector3<f64>, Option<usize>), ModelError> {
        match frame {
            Frame::World => Ok((Vector3::zeros(), None)),
            Frame::Cog => Ok((ws.cog, None)),
            Frame::Link(l) if l < self.links.len() => {
                Ok((ws.link_pose[l].translation.vector, Some(l)))
            }
            Frame::Rotor(r) if r < self.rotors.len() => {
                Ok((ws.rotor_position[r], Some(self.rotors[r].link)))
            }
            _ => Err(ModelError::UnknownFrame(format!("{frame:?}"))),
        }
    }

    /// Foot frame pose w.r.t. the CoG frame (for the perching controller).
    pub fn foot_in_cog(&self, ws: &ModelWorkspace) -> Result<Isometry3<f64>, ModelError> {
        let foot = self.frame_pose(ws, Frame::Link(self.foot_link))?;
        Ok(ws.cog_pose().inverse() * foot)
    }

    /// Rotation C<-L_i of vectoring apparatus `unit`'s parent link frame (eq. 36).
    pub fn unit_parent_rotation(
        &self,
        ws: &ModelWorkspace,
        unit: usize,
    ) -> Result<Rotation3<f64>, ModelError> {
        if !ws.evaluated {
            return Err(ModelError::NotEvaluated);
        }
        let u = self.units.get(unit).ok_or(ModelError::UnknownUnit(unit))?;
        Ok((ws.cog_rotation.inverse() * ws.link_pose[u.parent_link].rotation).to_rotation_matrix())
    }
}
