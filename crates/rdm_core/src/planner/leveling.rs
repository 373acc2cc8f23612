//! Keep every vectoring apparatus level (Sec. III-A: "we assume that the vectoring
//! apparatus is horizontal in the world coordinate"): solve its roll alpha and pitch beta
//! so that the rotor axes point straight up. The planner treats alpha, beta as functions
//! of the other state variables, never as free QP variables.
//!
//! Closed form for a roll joint about x followed by a pitch joint about y with rotors
//! along z: R_mount Rx(alpha) Ry(beta) z = world z gives, with d = R_mountᵀ z,
//! beta = asin(d_x), alpha = atan2(-d_y, d_z). `Leveler::new` checks that structure.

use nalgebra::{UnitQuaternion, Vector3};

use crate::model::{ModelWorkspace, RobotDescription};

/// One unit's leveling data.
#[derive(Clone, Debug)]
struct Unit {
    roll_q: usize,
    pitch_q: usize,
    parent_link: usize,
    mount_rotation: UnitQuaternion<f64>,
}

/// Leveling solver for all vectoring units of a robot.
#[derive(Clone, Debug)]
pub struct Leveler {
    units: Vec<Unit>,
}

fn near(a: &Vector3<f64>, b: &Vector3<f64>) -> bool {
    (a - b).norm() < 1e-9
}

impl Leveler {
    /// Check the unit structure (roll about x, pitch about y, rotors along z, no rotation
    /// between the roll and pitch frames) and record the mounts. `Err` names the unit.
    pub fn new(robot: &RobotDescription) -> Result<Self, String> {
        let mut units = Vec::with_capacity(robot.units.len());
        for u in &robot.units {
            let roll = robot
                .q_joint
                .get(u.roll_q)
                .and_then(|&j| robot.joints.get(j))
                .ok_or_else(|| format!("unit '{}': roll joint missing", u.name))?;
            let pitch = robot
                .q_joint
                .get(u.pitch_q)
                .and_then(|&j| robot.joints.get(j))
                .ok_or_else(|| format!("unit '{}': pitch joint missing", u.name))?;
            let ok = roll.axis.is_some_and(|a| near(&a, &Vector3::x()))
                && pitch.axis.is_some_and(|a| near(&a, &Vector3::y()))
                && pitch.origin.rotation.angle() < 1e-9
                && pitch.parent_link == roll.child_link
                && u.rotors.iter().all(|&r| {
                    robot.rotors.get(r).is_some_and(|rotor| {
                        rotor.link == pitch.child_link && near(&rotor.axis, &Vector3::z())
                    })
                });
            if !ok {
                return Err(format!(
                    "unit '{}': leveling needs roll about x, pitch about y, rotors along z",
                    u.name
                ));
            }
            units.push(Unit {
                roll_q: u.roll_q,
                pitch_q: u.pitch_q,
                parent_link: roll.parent_link,
                mount_rotation: roll.origin.rotation,
            });
        }
        Ok(Self { units })
    }

    /// Whether `q` index `i` is a unit angle (not a free planning variable).
    pub fn is_unit_angle(&self, i: usize) -> bool {
        self.units.iter().any(|u| u.roll_q == i || u.pitch_q == i)
    }

    /// Overwrite the unit angles in `q` from the parent link poses in `ws` (which must be
    /// evaluated; the parent links do not depend on their own unit's angles).
    pub fn level(&self, ws: &ModelWorkspace, q: &mut [f64]) {
        for u in &self.units {
            let Some(parent) = ws.link_pose.get(u.parent_link) else {
                continue;
            };
            let mount = parent.rotation * u.mount_rotation;
            let d = mount.inverse() * Vector3::z();
            let beta = d.x.clamp(-1.0, 1.0).asin();
            let alpha = (-d.y).atan2(d.z);
            if let Some(a) = q.get_mut(u.roll_q) {
                *a = alpha;
            }
            if let Some(b) = q.get_mut(u.pitch_q) {
                *b = beta;
            }
        }
    }
}
