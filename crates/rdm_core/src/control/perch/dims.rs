//! The size of the perching QP of eq. (49), shared by the row builder ([`super::qp`]) and the
//! reduction to the thrusts ([`super::reduced`]).

use crate::PERCH_ROTORS;

/// Decision variables: 4 thrusts and the 4 components of `W_foot,t`.
pub const N_VARS: usize = PERCH_ROTORS + 4;
/// Equality rows (zero cone), eq. (38).
pub const N_ZERO_ROWS: usize = 4;
/// All rows.
pub const N_ROWS: usize = 29;
