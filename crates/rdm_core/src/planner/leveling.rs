//! Keep every vectoring apparatus level (Sec. III-A: "we assume that the vectoring
//! apparatus is horizontal in the world coordinate"): solve its roll alpha and pitch beta
//! so that the rotor axes point straight up. The planner treats alpha, beta as functions
//! of the other state variables, never as free QP variables.
//!
//! Closed form for a roll joint about x followed by a pitch joint about y with rotors
//! along z: R_mount Rx(alpha) Ry(beta) z = world z, with d = R_mountᵀ z, has two
//! solutions (alpha, beta) and (alpha + pi, pi - beta). They thrust identically but the
//! second turns the rotor pair by 180 deg about the thrust axis, which swaps the pair's
//! rotors and, with the diagonal spin layout, decides whether equal spins sit on a diagonal
//! (regular allocation) or on one side (rank-deficient Q̄, rho = 0). The branch is chosen by
//! continuity with the angles already in `q` (the planner's previous step, or the start
//! state: unit angles near 0 select the branch that keeps the pair along the parent link's
//! y axis). At gimbal lock (d = ±x, thrust along the link) alpha is free: the given alpha is
//! kept, so e.g. `VERTICAL_Q`'s alpha2 = 90 deg survives. `Leveler::new` checks the structure.

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
            let prev_alpha = q.get(u.roll_q).copied().unwrap_or(0.0);
            let prev_beta = q.get(u.pitch_q).copied().unwrap_or(0.0);
            let (alpha, beta) = level_angles(&d, prev_alpha, prev_beta);
            if let Some(a) = q.get_mut(u.roll_q) {
                *a = alpha;
            }
            if let Some(b) = q.get_mut(u.pitch_q) {
                *b = beta;
            }
        }
    }
}

/// Wrapped angle difference in [0, pi].
fn angle_gap(a: f64, b: f64) -> f64 {
    let r = (a - b).rem_euclid(std::f64::consts::TAU);
    r.min(std::f64::consts::TAU - r)
}

/// Wrap to (-pi, pi].
fn wrap(a: f64) -> f64 {
    let r = a.rem_euclid(std::f64::consts::TAU);
    if r > std::f64::consts::PI {
        r - std::f64::consts::TAU
    } else {
        r
    }
}

/// (alpha, beta) with Rx(alpha) Ry(beta) z = `d` (unit), on the branch nearest to
/// (`prev_alpha`, `prev_beta`). Non-finite previous angles select the alpha-near-0 branch.
fn level_angles(d: &Vector3<f64>, prev_alpha: f64, prev_beta: f64) -> (f64, f64) {
    let (pa, pb) = if prev_alpha.is_finite() && prev_beta.is_finite() {
        (prev_alpha, prev_beta)
    } else {
        (0.0, 0.0)
    };
    let lateral = d.y.hypot(d.z);
    if lateral < 1e-9 {
        // Gimbal lock: thrust along the link's x axis whatever alpha is.
        return (wrap(pa), d.x.clamp(-1.0, 1.0).asin());
    }
    let alpha_a = (-d.y).atan2(d.z);
    let beta_a = d.x.atan2(lateral);
    let alpha_b = wrap(alpha_a + std::f64::consts::PI);
    let beta_b = wrap(std::f64::consts::PI - beta_a);
    let gap_a = angle_gap(alpha_a, pa) + angle_gap(beta_a, pb);
    let gap_b = angle_gap(alpha_b, pa) + angle_gap(beta_b, pb);
    if gap_b < gap_a {
        (alpha_b, beta_b)
    } else {
        (alpha_a, beta_a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn thrust_dir(alpha: f64, beta: f64) -> Vector3<f64> {
        let r = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), alpha)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), beta);
        r * Vector3::z()
    }

    #[test]
    fn both_branches_level_and_continuity_picks_the_nearest() {
        let d = Vector3::new(0.3, -0.2, -0.9).normalize();
        for (pa, pb) in [(0.0, 0.0), (3.0, -1.0), (-3.0, 2.0)] {
            let (a, b) = level_angles(&d, pa, pb);
            assert!((thrust_dir(a, b) - d).norm() < 1e-12);
            let (a2, b2) = (
                wrap(a + std::f64::consts::PI),
                wrap(std::f64::consts::PI - b),
            );
            assert!((thrust_dir(a2, b2) - d).norm() < 1e-12);
            assert!(angle_gap(a, pa) + angle_gap(b, pb) <= angle_gap(a2, pa) + angle_gap(b2, pb));
        }
        // Start near zero: the pair stays along the link's y axis (|alpha| <= pi/2).
        let (a, _) = level_angles(&d, 0.0, 0.0);
        assert!(a.abs() <= std::f64::consts::FRAC_PI_2);
    }

    #[test]
    fn gimbal_lock_keeps_the_given_alpha() {
        let d = -Vector3::x();
        let (a, b) = level_angles(&d, 1.2, 0.0);
        assert_eq!(a, 1.2);
        assert!((thrust_dir(a, b) - d).norm() < 1e-12);
    }
}
