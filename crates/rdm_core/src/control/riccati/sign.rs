//! Cold CARE method: Newton iteration for the sign of the Hamiltonian.
//!
//! `H = [[A, −G], [−Q, −Aᵀ]]`, `Z_{k+1} = (c Z_k + Z_k⁻¹ / c) / 2` with the determinant
//! scaling `c = |det Z_k|^(−1/2n)` (switched off once the iterates settle, so that the
//! final convergence is quadratic). With `W = sign(H)` the stable invariant subspace is
//! `ker(W + I)`, spanned by `[I; P]`, so P solves the over-determined but consistent
//! system `[W12; W22 + I] P = −[W11 + I; W21]`, solved here by QR.

use nalgebra::SMatrix;

use super::dense::{invert_in_place, norm1, InversionError};
use super::{CareConfig, CareError, CareProblem, StateMatrix, N_STATE};

const N_HAMILTONIAN: usize = 2 * N_STATE;
type Hamiltonian = SMatrix<f64, N_HAMILTONIAN, N_HAMILTONIAN>;
type Stacked = SMatrix<f64, N_HAMILTONIAN, N_STATE>;

/// Relative step below which the iteration has converged (quadratic phase).
const STEP_TOLERANCE: f64 = 1e-12;
/// Relative step below which determinant scaling is switched off.
const SCALING_OFF: f64 = 1e-2;

/// Returns the stabilising P and the number of sign iterations.
pub(super) fn solve(
    problem: &CareProblem,
    config: &CareConfig,
) -> Result<(StateMatrix, usize), CareError> {
    let n = N_STATE;
    let mut z = Hamiltonian::zeros();
    z.fixed_view_mut::<N_STATE, N_STATE>(0, 0)
        .copy_from(&problem.a);
    z.fixed_view_mut::<N_STATE, N_STATE>(0, n)
        .copy_from(&(-problem.g));
    z.fixed_view_mut::<N_STATE, N_STATE>(n, 0)
        .copy_from(&(-problem.q));
    z.fixed_view_mut::<N_STATE, N_STATE>(n, n)
        .copy_from(&(-problem.a.transpose()));

    let mut scaling = true;
    let mut converged = false;
    let mut iterations = 0;
    // Converged once the step is tiny; one extra step then drives the error to eps.
    let mut extra_steps_left = 1;
    while iterations < config.max_sign_iterations {
        iterations += 1;
        let mut z_inv = z;
        let log_det = invert_in_place(&mut z_inv).map_err(|e| match e {
            InversionError::Singular => CareError::NotStabilizable,
            InversionError::NotFinite => CareError::NotConverged { iterations },
        })?;
        let c = if scaling {
            (-log_det / N_HAMILTONIAN as f64).exp()
        } else {
            1.0
        };
        if !c.is_finite() || c <= 0.0 {
            return Err(CareError::NotConverged { iterations });
        }
        let next = (z * c + z_inv * (1.0 / c)) * 0.5;
        let step = norm1(&(next - z));
        let size = norm1(&next);
        z = next;
        if !size.is_finite() {
            return Err(CareError::NotConverged { iterations });
        }
        if step <= SCALING_OFF * size {
            scaling = false;
        }
        if converged {
            extra_steps_left -= 1;
            if extra_steps_left == 0 {
                break;
            }
        } else if step <= STEP_TOLERANCE.sqrt() * size {
            // Quadratic phase reached: the next step squares the error.
            converged = true;
        }
    }
    if !converged {
        return Err(CareError::NotConverged { iterations });
    }

    let mut lhs = Stacked::zeros();
    let mut rhs = Stacked::zeros();
    let identity = StateMatrix::identity();
    lhs.fixed_view_mut::<N_STATE, N_STATE>(0, 0)
        .copy_from(&z.fixed_view::<N_STATE, N_STATE>(0, n));
    lhs.fixed_view_mut::<N_STATE, N_STATE>(n, 0)
        .copy_from(&(z.fixed_view::<N_STATE, N_STATE>(n, n) + identity));
    rhs.fixed_view_mut::<N_STATE, N_STATE>(0, 0)
        .copy_from(&(-(z.fixed_view::<N_STATE, N_STATE>(0, 0) + identity)));
    rhs.fixed_view_mut::<N_STATE, N_STATE>(n, 0)
        .copy_from(&(-z.fixed_view::<N_STATE, N_STATE>(n, 0)));

    let qr = lhs.qr();
    let r = qr.r();
    let qt_rhs = qr.q().transpose() * rhs;
    // A rank-deficient R means the stable subspace is not a graph [I; P].
    let r_scale = r.amax();
    if !(r_scale.is_finite() && r_scale > 0.0)
        || r.diagonal()
            .iter()
            .any(|d| d.abs() <= 1e-13 * r_scale || !d.is_finite())
    {
        return Err(CareError::NotStabilizable);
    }
    let p = r
        .solve_upper_triangular(&qt_rhs)
        .ok_or(CareError::NotStabilizable)?;
    let p = (p + p.transpose()) * 0.5;
    if p.iter().any(|v| !v.is_finite()) {
        return Err(CareError::NotConverged { iterations });
    }
    Ok((p, iterations))
}
