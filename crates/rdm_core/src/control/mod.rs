//! Flight and perching control of Sec. IV.
//!
//! - [`gains`]: the per-rotor gain set the PC computes and Spinal applies.
//! - [`lqi`], [`riccati`]: LQI attitude/altitude gain synthesis (eqs. 21-29).
//! - [`attitude`]: the Spinal-side attitude step as the firmware splits it.
//! - [`position`]: horizontal position control and vectoring angles (eqs. 30-36).
//! - [`perch`]: the perching QP (eqs. 37-49).

pub mod attitude;
pub mod gains;
pub mod lqi;
pub mod perch;
pub mod position;
pub mod riccati;
