//! Robot description and the quasi-steady model of Sec. III: kinematics, mass properties,
//! rotor allocation Q(q) (eqs. 7-9), aerial ZMP (eq. 73, ASP eq. 1), static joint torques
//! (eq. 61), Jacobians w.r.t. zeta (eq. 53) and the stability measure (eq. 65).
//!
//! Usage: load a [`RobotDescription`] once, build a [`ModelWorkspace`] for it, then call
//! [`RobotDescription::evaluate`] with (q, base pose) and query the workspace. After setup
//! nothing allocates, and bad input returns a [`ModelError`], never a panic.

mod aerial_zmp;
mod allocation;
pub mod bounds;
mod config;
mod description;
mod error;
mod jacobian;
mod kinematics;
mod mass;
mod rules;
mod stability;
mod statics;
mod urdf;
mod workspace;

pub use aerial_zmp::{support_margin, AerialZmp};
pub use allocation::{allocation_bar, Matrix4xN};
pub use description::{Joint, Link, RobotDescription, Rotor, VectoringUnit, WrenchSensor};
pub use error::{DescriptionError, DescriptionErrorKind, ModelError};
pub use kinematics::{base_pose_from_zeta, Frame};
pub use rules::KNOWN_WRENCH_SENSORS;
pub use stability::STABILITY_FD_STEP;
pub use statics::StaticLoads;
pub use workspace::{Matrix6xN, ModelWorkspace};

#[cfg(test)]
mod tests;
