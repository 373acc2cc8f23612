//! `rdm_core`: the deterministic real-time core of the rotor-distributed manipulator (RDM)
//! of Nishio, Zhao, Okada and Inaba, "Design, Control, and Motion-Planning for a
//! Root-Perching Rotor-Distributed Manipulator".
//!
//! Pure Rust, no Python. Every step function allocates nothing after setup, runs a
//! bounded number of iterations and returns a typed status instead of panicking.
//! Equation numbers in comments refer to the paper.

pub mod control;
pub mod estimate;
pub mod model;
pub mod pwm;
