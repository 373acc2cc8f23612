//! Differential-kinematics motion planner of Sec. V (eqs. 50-70) and the feasible
//! end-effector force of Sec. II-A-2 (eq. 3).
//!
//! State zeta = [p, eta, q] (eq. 51). Each step solves one dense QP (eqs. 69-70) over the
//! free part of delta-zeta: the cost of eq. (57) (end-effector and foot tasks plus the
//! S1 regulariser) and one linear row block per constraint (eqs. 58-68), each built by its
//! own [`constraints`] object. The vectoring-apparatus angles are not free: as in the
//! paper's model (Sec. III-A, "the vectoring apparatus is horizontal"), they are re-solved
//! after every step so that every rotor thrusts straight up ([`leveling`]).

pub mod config;
pub mod constraints;
pub mod damper;
pub mod force;
pub mod leveling;
pub mod quantities;
pub mod shapes;
pub mod step;
pub mod target;
pub mod thrust;

pub use config::{DamperParams, Mode, PlannerConfig, ShapePair, ShapeSpec};
pub use force::{feasible_force, FeasibleForce};
pub use quantities::{Quantities, QuantityLayout};
pub use step::{Planner, PlannerError, StepReport, StepStatus};
pub use target::{EeOrientation, TaskErrors, TaskRows};
