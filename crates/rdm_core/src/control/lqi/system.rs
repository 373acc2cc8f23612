//! The augmented linear model of eqs. (21)-(26) in the JSK state order.
//!
//! State `x̄ = [z, ż, φ, φ̇, θ, θ̇, ψ, ψ̇, ∫z, ∫φ, ∫θ, ∫ψ]` (JSK `lqi_mode` 4). The paper
//! orders the same quantities as `[ξ̄; ξ̄̇; v]` with `ξ̄ = [z, φ, θ, ψ]`; see
//! [`JSK_TO_PAPER`]. Input: the per-rotor thrust deviations `λ̄_flight` (eq. 24).

use nalgebra::{Cholesky, Matrix3, SMatrix};

use super::LqiError;
use crate::control::riccati::{InputMatrix, StateMatrix, N_STATE};
use crate::MAX_ROTORS;

/// Allocation matrix `Q̄(q)`: rows `f_z, m_x, m_y, m_z` in the CoG frame (rows 3-6 of eq. 8),
/// one column per rotor; the columns past the rotor count are not read.
pub type Allocation = SMatrix<f64, 4, MAX_ROTORS>;

/// `JSK_TO_PAPER[i]` is the paper's index (in `x̄ = [ξ̄; ξ̄̇; v]`, eq. 26) of JSK state `i`.
pub const JSK_TO_PAPER: [usize; N_STATE] = [0, 4, 1, 5, 2, 6, 3, 7, 8, 9, 10, 11];

/// Number of controlled axes (z, roll, pitch, yaw).
const N_AXES: usize = 4;

/// `Ā` of eq. (26): double integrators per axis and `v̇ = −C e` (eq. 25).
pub fn augmented_state_matrix() -> StateMatrix {
    let mut a = StateMatrix::zeros();
    for axis in 0..N_AXES {
        // d/dt position = rate
        a[(2 * axis, 2 * axis + 1)] = 1.0;
        // d/dt integral = −position error
        a[(2 * N_AXES + axis, 2 * axis)] = -1.0;
    }
    a
}

/// `B̄(q)` of eq. (26): rows ż̇ = f_z/m and the angular accelerations `I⁻¹[m_x, m_y, m_z]`.
///
/// Checks its inputs: mass finite and positive, inertia finite, symmetric and positive
/// definite, allocation finite. Columns of B past `rotors` (in `1..=MAX_ROTORS`) stay zero.
pub fn augmented_input_matrix(
    mass: f64,
    inertia: &Matrix3<f64>,
    allocation: &Allocation,
    rotors: usize,
) -> Result<InputMatrix, LqiError> {
    if crate::check_rotor_count(rotors).is_err() {
        return Err(LqiError::InvalidInput { argument: "rotors" });
    }
    if !(mass.is_finite() && mass > 0.0) {
        return Err(LqiError::InvalidInput { argument: "mass" });
    }
    let inertia_inv = inertia_inverse(inertia)?;
    if allocation.columns(0, rotors).iter().any(|v| !v.is_finite()) {
        return Err(LqiError::InvalidInput {
            argument: "allocation",
        });
    }
    let moments = allocation.fixed_rows::<3>(1);
    let angular = inertia_inv * moments;
    let mut b = InputMatrix::zeros();
    for rotor in 0..rotors {
        b[(1, rotor)] = allocation[(0, rotor)] / mass;
        for axis in 0..3 {
            b[(2 * (axis + 1) + 1, rotor)] = angular[(axis, rotor)];
        }
    }
    Ok(b)
}

/// Inverse of a symmetric positive definite inertia tensor, or `InvalidInput("inertia")`.
pub(crate) fn inertia_inverse(inertia: &Matrix3<f64>) -> Result<Matrix3<f64>, LqiError> {
    let invalid = LqiError::InvalidInput {
        argument: "inertia",
    };
    if inertia.iter().any(|v| !v.is_finite()) {
        return Err(invalid);
    }
    if (inertia - inertia.transpose()).amax() > 1e-9 * inertia.amax() {
        return Err(invalid);
    }
    Cholesky::new(*inertia).map(|c| c.inverse()).ok_or(invalid)
}
