//! Gyro-moment compensation: the `Q̄⁻¹[0; ω×Iω]` term of eq. (29) and the data Spinal
//! needs to apply it itself (`p_matrix_pseudo_inverse_inertia`, sec. 4 and 3.4).

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use super::system::{inertia_inverse, Allocation};
use super::LqiError;
use crate::control::riccati::{GainMatrix, N_STATE};
use crate::MAX_ROTORS;

/// Per-rotor thrusts (entries past the rotor count zero).
pub type RotorVector = SVector<f64, MAX_ROTORS>;
/// The LQI state `x̄` in JSK order.
pub type LqiState = SVector<f64, N_STATE>;

/// How `Q̄⁻¹` was formed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AllocationInverse {
    /// `Q̄` is regular: the plain inverse (equal to the pseudo-inverse).
    Exact,
    /// `Q̄` is (numerically) rank deficient: the Moore-Penrose pseudo-inverse was used.
    PseudoInverse {
        /// Numerical rank of `Q̄`.
        rank: usize,
    },
}

/// `pinv(Q̄)` columns and the inertia: what `p_matrix_pseudo_inverse_inertia` carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GyroCompensation {
    /// Column 1 of `pinv(Q̄)` (roll moment to rotor thrust).
    pub pinv_roll: RotorVector,
    /// Column 2 of `pinv(Q̄)` (pitch moment).
    pub pinv_pitch: RotorVector,
    /// Column 3 of `pinv(Q̄)` (yaw moment).
    pub pinv_yaw: RotorVector,
    /// Inertia tensor in the CoG frame.
    pub inertia: Matrix3<f64>,
    /// Whether `Q̄` was inverted exactly or pseudo-inverted.
    pub inverse: AllocationInverse,
}

/// Relative singular-value threshold below which `Q̄` counts as rank deficient.
const RANK_TOLERANCE: f64 = 1e-10;
/// Bound on the SVD sweeps (nalgebra's own iteration bound).
const SVD_MAX_ITERATIONS: usize = 200;
// The size dispatch of `GyroCompensation::new` covers 1..=8.
const _: () = assert!(MAX_ROTORS == 8);

/// `pinv` of the first `$n` columns of an allocation (rows past `$n` zero) and its rank, at
/// the literal size `$n` (nalgebra's SVD bounds need a concrete dimension).
macro_rules! pseudo_inverse {
    ($allocation:expr, $n:literal) => {{
        let a: SMatrix<f64, 4, $n> = $allocation.fixed_columns::<$n>(0).into_owned();
        let svd = nalgebra::SVD::try_new(a, true, true, f64::EPSILON, SVD_MAX_ITERATIONS)
            .ok_or(LqiError::SingularAllocation)?;
        let largest = svd.singular_values.max();
        let threshold = RANK_TOLERANCE * largest;
        let rank = svd.rank(threshold);
        if rank == 0 {
            return Err(LqiError::SingularAllocation);
        }
        let pinv: SMatrix<f64, $n, 4> = svd
            .pseudo_inverse(threshold)
            .map_err(|_| LqiError::SingularAllocation)?;
        let mut out = SMatrix::<f64, MAX_ROTORS, 4>::zeros();
        out.fixed_rows_mut::<$n>(0).copy_from(&pinv);
        (out, rank)
    }};
}

impl GyroCompensation {
    /// Pseudo-inverts the first `rotors` columns of the allocation (`rotors` in
    /// `1..=MAX_ROTORS`) and keeps the inertia.
    pub fn new(
        allocation: &Allocation,
        inertia: &Matrix3<f64>,
        rotors: usize,
    ) -> Result<Self, LqiError> {
        if crate::check_rotor_count(rotors).is_err() {
            return Err(LqiError::InvalidInput { argument: "rotors" });
        }
        if allocation.columns(0, rotors).iter().any(|v| !v.is_finite()) {
            return Err(LqiError::InvalidInput {
                argument: "allocation",
            });
        }
        inertia_inverse(inertia)?;
        // The SVD runs at the robot's own size (a zero column would change its rounding).
        let (pinv, rank) = match rotors {
            1 => pseudo_inverse!(allocation, 1),
            2 => pseudo_inverse!(allocation, 2),
            3 => pseudo_inverse!(allocation, 3),
            4 => pseudo_inverse!(allocation, 4),
            5 => pseudo_inverse!(allocation, 5),
            6 => pseudo_inverse!(allocation, 6),
            7 => pseudo_inverse!(allocation, 7),
            _ => pseudo_inverse!(allocation, 8),
        };
        let inverse = if rank == 4 {
            AllocationInverse::Exact
        } else {
            AllocationInverse::PseudoInverse { rank }
        };
        Ok(Self {
            pinv_roll: pinv.column(1).into_owned(),
            pinv_pitch: pinv.column(2).into_owned(),
            pinv_yaw: pinv.column(3).into_owned(),
            inertia: *inertia,
            inverse,
        })
    }

    /// `Q̄⁻¹[0; ω × Iω]`: the thrusts that cancel the gyroscopic moment.
    pub fn thrust(&self, omega: &Vector3<f64>) -> RotorVector {
        let moment = omega.cross(&(self.inertia * omega));
        self.pinv_roll * moment.x + self.pinv_pitch * moment.y + self.pinv_yaw * moment.z
    }
}

/// Eq. (29): `λ_flight = K x̄ + Q̄⁻¹[0; ω×Iω]`.
pub fn flight_thrust(
    k: &GainMatrix,
    state: &LqiState,
    gyro: &GyroCompensation,
    omega: &Vector3<f64>,
) -> Result<RotorVector, LqiError> {
    if state.iter().any(|v| !v.is_finite()) {
        return Err(LqiError::InvalidInput { argument: "state" });
    }
    if omega.iter().any(|v| !v.is_finite()) {
        return Err(LqiError::InvalidInput { argument: "omega" });
    }
    Ok(k * state + gyro.thrust(omega))
}
