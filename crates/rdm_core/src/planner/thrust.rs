//! Static thrust distribution used by the torque and thrust constraints (derivation in
//! docs/planner.md). With level units every rotor thrusts along world z, so the world
//! allocation about a point r0 has columns [u_z; (p_i - r0) x u_i - c sigma_i u_i]
//! (rows fz, mx, my, mz; eqs. 7-9 in world axes).
//!
//! * Gravity share: lambda_g = Q̄(cog)⁻¹ [m g, 0, 0, 0]: weight carried, no moment about
//!   the CoG (the hover distribution, identical in flight and perched, eq. 47's term).
//! * Perching share (perched only): lambda_p = Q̄(foot)⁻¹ [F_perch, 0, 0, 0]: a pure
//!   upward force through the foot centre, so the ceiling's reaction is the normal force
//!   F_perch at the plate centre (ZMP at the centre, eq. 42 margin maximal).
//! * Perching upper limit (eq. 64): lambda_max - Q̄(foot)⁻¹ [|F_ee,xy| / mu, 0, 0, 0].

use nalgebra::{Matrix4, Vector3, Vector4};

use crate::model::{ModelWorkspace, RobotDescription};

/// World allocation (rows fz, mx, my, mz) about `r0`.
pub fn world_allocation(
    robot: &RobotDescription,
    ws: &ModelWorkspace,
    r0: &Vector3<f64>,
) -> Matrix4<f64> {
    let mut q = Matrix4::zeros();
    for (i, rotor) in robot.rotors.iter().take(4).enumerate() {
        let u = ws.rotor_direction[i];
        let m = (ws.rotor_position[i] - r0).cross(&u) - rotor.drag_to_thrust * rotor.spin * u;
        q[(0, i)] = u.z;
        q[(1, i)] = m.x;
        q[(2, i)] = m.y;
        q[(3, i)] = m.z;
    }
    q
}

/// Result of the distribution at one configuration.
#[derive(Clone, Copy, Debug)]
pub struct StaticThrust {
    /// lambda (gravity share plus, perched, the perching share) [N].
    pub thrust: Vector4<f64>,
    /// Upper thrust limit (eq. 64 when perched, lambda_max in flight) [N].
    pub upper: Vector4<f64>,
    /// rho_stable = sqrt(det(Q̄ Q̄ᵀ)) = |det Q̄| about the CoG (eq. 65).
    pub rho: f64,
}

/// Distribute thrust; `None` if the allocation is singular (rho = 0).
pub fn static_thrust(
    robot: &RobotDescription,
    ws: &ModelWorkspace,
    gravity: f64,
    perch_force: Option<f64>,
    ee_force: &[f64; 3],
) -> Option<StaticThrust> {
    let q_cog = world_allocation(robot, ws, &ws.cog);
    let rho = q_cog.determinant().abs();
    let inv_cog = q_cog.try_inverse()?;
    let mut thrust = inv_cog * Vector4::new(ws.mass * gravity, 0.0, 0.0, 0.0);
    let mut upper = Vector4::from_fn(|i, _| robot.rotors.get(i).map_or(0.0, |r| r.thrust_max));
    if let Some(f_perch) = perch_force {
        let foot = ws.link_pose[robot.foot_link].translation.vector;
        let inv_foot = world_allocation(robot, ws, &foot).try_inverse()?;
        thrust += inv_foot * Vector4::new(f_perch, 0.0, 0.0, 0.0);
        let tangential = (ee_force[0].powi(2) + ee_force[1].powi(2)).sqrt();
        let mu = robot.friction_xy.max(1e-6);
        upper -= inv_foot * Vector4::new(tangential / mu, 0.0, 0.0, 0.0);
    }
    Some(StaticThrust { thrust, upper, rho })
}
