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

/// Capacity of the rotor storage of the real-time controllers (Spinal's `MAX_MOTOR_NUMBER`
/// in the same role): the 200 Hz and 40 Hz steps keep fixed-size arrays and matrices of this
/// size and use the first `rotors` entries, the count fixed when they are built
/// ([`check_rotor_count`]). Entries past the count stay zero.
pub const MAX_ROTORS: usize = 8;

/// Rotors of the perching QP (eqs. 37-49).
///
/// ASSUMPTION: the perching controller is built for the paper's RDM, four rotors on two
/// dual-rotor vectoring apparatuses; a robot with another count flies (LQI, attitude,
/// position control) but has no perching controller.
pub const PERCH_ROTORS: usize = 4;

/// A rotor count outside `1..=MAX_ROTORS`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RotorCountError {
    /// The count given.
    pub rotors: usize,
}

impl core::fmt::Display for RotorCountError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "rotor count {} is not in 1..={MAX_ROTORS}", self.rotors)
    }
}

impl std::error::Error for RotorCountError {}

/// `rotors` if it is in `1..=MAX_ROTORS`, else the typed error.
pub fn check_rotor_count(rotors: usize) -> Result<usize, RotorCountError> {
    if (1..=MAX_ROTORS).contains(&rotors) {
        Ok(rotors)
    } else {
        Err(RotorCountError { rotors })
    }
}
