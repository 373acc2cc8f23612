//! Mass properties: total mass m, CoG, and I(q) about the CoG in the CoG frame (eq. 6).

use nalgebra::Matrix3;

use super::description::RobotDescription;
use super::workspace::ModelWorkspace;

impl RobotDescription {
    /// Fill mass, CoG and inertia from the link poses already in `ws`.
    pub(crate) fn fill_mass_properties(&self, ws: &mut ModelWorkspace) {
        let mut mass = 0.0;
        let mut moment = nalgebra::Vector3::zeros();
        for (link, pose) in self.links.iter().zip(&ws.link_pose) {
            mass += link.mass;
            moment += link.mass * pose.transform_point(&link.com.into()).coords;
        }
        // A massless description has no CoG; use the base origin so nothing is NaN.
        let cog = if mass > 0.0 {
            moment / mass
        } else {
            ws.base.translation.vector
        };
        let mut inertia = Matrix3::zeros();
        for (link, pose) in self.links.iter().zip(&ws.link_pose) {
            let r = pose.rotation.to_rotation_matrix();
            let d = pose.transform_point(&link.com.into()).coords - cog;
            // Rotate the link inertia to world axes, then shift it to the CoG (parallel axes).
            inertia += r.matrix() * link.inertia * r.matrix().transpose()
                + link.mass * (Matrix3::identity() * d.norm_squared() - d * d.transpose());
        }
        let rc = ws.cog_rotation.to_rotation_matrix();
        ws.mass = mass;
        ws.cog = cog;
        ws.inertia_world = inertia;
        ws.inertia = rc.matrix().transpose() * inertia * rc.matrix();
    }
}
