//! `rdm_core`: the deterministic real-time core of the rotor-distributed manipulator (RDM)
//! of Nishio, Zhao, Okada and Inaba, "Design, Control, and Motion-Planning for a
//! Root-Perching Rotor-Distributed Manipulator".
//!
//! Pure Rust, no Python. Every step function allocates nothing after setup, runs a
//! bounded number of iterations and returns a typed status instead of panicking.
//! Equation numbers in comments refer to the paper.

pub mod control;
pub mod estimate;
pub mod firmware;
pub mod model;
pub mod planner;
pub mod pwm;
pub mod qp;
pub mod sim;

/// Number of rotors the real-time controllers are built for.
///
/// Assumption: the paper's RDM and its RCM comparison robot both have four rotors
/// (two dual-rotor vectoring apparatuses), so the 200 Hz and 40 Hz steps use fixed-size
/// matrices of this size. The model itself reads any number of rotors from the
/// description; building a controller for a robot with another count is a setup error.
pub const N_ROTORS: usize = 4;
