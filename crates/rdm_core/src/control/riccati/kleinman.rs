//! Warm CARE method: Kleinman's Newton iteration on the gain.
//!
//! From a stabilising `K_0` (`u = K x`): solve the Lyapunov equation
//! `(A + BK_j)ᵀP_j + P_j(A + BK_j) + Q + K_jᵀRK_j = 0`, set `K_{j+1} = −R⁻¹BᵀP_j`, until
//! `max|ΔK|` is below the tolerance. Each Lyapunov equation is solved by the Roberts
//! sign-function iteration, which also detects a non-stabilising `K_j` (the closed loop
//! sign is then not −I) so the caller can fall back to the cold method.

use super::dense::{invert_in_place, mul_into, norm1, transpose_into};
use super::{
    CareConfig, CareError, CareProblem, GainMatrix, InputWeight, StateMatrix, N_INPUT, N_STATE,
};

/// Step below which the Roberts iteration has converged.
const LYAPUNOV_STEP_TOLERANCE: f64 = 1e-7;
/// Relative step below which determinant scaling is switched off.
const SCALING_OFF: f64 = 1e-2;

/// Outcome of a bounded Kleinman run.
pub(super) struct KleinmanOutcome {
    /// Last P computed (from a stabilising gain).
    pub p: StateMatrix,
    /// Iterations performed.
    pub iterations: usize,
    /// Whether `max|ΔK|` fell below the tolerance.
    pub converged: bool,
}

/// Runs at most `max_kleinman_iterations` Newton steps from `k0`. Errors if `k0` (or an
/// iterate) is not stabilising, so no P is available.
pub(super) fn solve(
    problem: &CareProblem,
    k0: &GainMatrix,
    config: &CareConfig,
) -> Result<KleinmanOutcome, CareError> {
    // R is recovered from R⁻¹ once; the gain update only needs R⁻¹.
    let mut r = problem.r_inv;
    if invert_in_place::<N_INPUT>(&mut r).is_err() {
        return Err(CareError::InvalidInput { argument: "r" });
    }
    let r: InputWeight = (r + r.transpose()) * 0.5;
    let mut k = *k0;
    let mut last_p = None;
    for iteration in 1..=config.max_kleinman_iterations {
        let closed_loop = problem.a + problem.b * k;
        let constant = problem.q + k.transpose() * r * k;
        let p = lyapunov(&closed_loop, &constant, config.max_lyapunov_iterations).ok_or(
            CareError::NotConverged {
                iterations: iteration,
            },
        )?;
        last_p = Some(p);
        let next = problem.gain(&p);
        let change = (next - k).amax();
        k = next;
        if !change.is_finite() {
            return Err(CareError::NotConverged {
                iterations: iteration,
            });
        }
        if change <= config.kleinman_tolerance * k.amax().max(1.0) {
            return Ok(KleinmanOutcome {
                p,
                iterations: iteration,
                converged: true,
            });
        }
    }
    last_p
        .map(|p| KleinmanOutcome {
            p,
            iterations: config.max_kleinman_iterations,
            converged: false,
        })
        .ok_or(CareError::NotConverged {
            iterations: config.max_kleinman_iterations,
        })
}

/// Solves `AᵀX + XA + C = 0` for a Hurwitz A (Roberts' sign iteration with determinant
/// scaling). Returns `None` if A is singular, not Hurwitz, or the bound is hit.
///
/// The iterates live in a fixed set of work matrices updated in place (no allocation).
fn lyapunov(a: &StateMatrix, c: &StateMatrix, max_iterations: usize) -> Option<StateMatrix> {
    // Invariant: A_kᵀX + XA_k + C_k = 0 for the same X; A_k → sign(A) = −I, C_k → 2X.
    let mut a_k = *a;
    let mut c_k = *c;
    let mut a_inv = StateMatrix::zeros();
    let mut a_inv_t = StateMatrix::zeros();
    let mut product = StateMatrix::zeros();
    let mut congruence = StateMatrix::zeros();
    let mut change = StateMatrix::zeros();
    let mut scaling = true;
    let mut converged = false;
    for _ in 0..max_iterations {
        a_inv.copy_from(&a_k);
        let log_det = invert_in_place(&mut a_inv).ok()?;
        let scale = if scaling {
            (-log_det / N_STATE as f64).exp()
        } else {
            1.0
        };
        if !scale.is_finite() || scale <= 0.0 {
            return None;
        }
        let inverse_scale = 1.0 / scale;
        // next_a = (a_k * scale + a_inv * (1 / scale)) * 0.5, and next_a - a_k
        for ((a, d), ai) in a_k
            .as_mut_slice()
            .iter_mut()
            .zip(change.as_mut_slice().iter_mut())
            .zip(a_inv.as_slice().iter())
        {
            let next = (*a * scale + ai * inverse_scale) * 0.5;
            *d = next - *a;
            *a = next;
        }
        // next_c = (c_k * scale + a_invᵀ c_k a_inv * (1 / scale)) * 0.5
        transpose_into(&a_inv, &mut a_inv_t);
        mul_into(&a_inv_t, &c_k, &mut product);
        mul_into(&product, &a_inv, &mut congruence);
        for (c, m) in c_k
            .as_mut_slice()
            .iter_mut()
            .zip(congruence.as_slice().iter())
        {
            *c = (*c * scale + m * inverse_scale) * 0.5;
        }
        let step = norm1(&change);
        let size = norm1(&a_k);
        if !size.is_finite() {
            return None;
        }
        if step <= SCALING_OFF * size {
            scaling = false;
        }
        if converged {
            break;
        }
        if step <= LYAPUNOV_STEP_TOLERANCE * size {
            converged = true;
        }
    }
    lyapunov_result(converged, &a_k, &c_k)
}

/// The converged iterates' solution `X = C_k / 2` (symmetrized), or `None` when the iteration
/// did not converge, A was not Hurwitz or X is not finite.
fn lyapunov_result(converged: bool, a_k: &StateMatrix, c_k: &StateMatrix) -> Option<StateMatrix> {
    if !converged {
        return None;
    }
    // A non-Hurwitz A converges to a sign matrix other than −I.
    let mut distance = *a_k;
    for i in 0..N_STATE {
        distance[(i, i)] += 1.0;
    }
    if norm1(&distance) > 1e-6 {
        return None;
    }
    let x = c_k * 0.5;
    let x = (x + x.transpose()) * 0.5;
    if x.iter().any(|v| !v.is_finite()) {
        return None;
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SMatrix;

    /// A small deterministic generator (no dev-dependency needed inside the crate).
    struct Lcg(u64);

    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        }
    }

    fn bits<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> Vec<u64> {
        m.iter().map(|v| v.to_bits()).collect()
    }

    #[test]
    fn mul_into_is_bitwise_nalgebra_product() {
        let mut g = Lcg(7);
        for _ in 0..200 {
            let a = StateMatrix::from_fn(|_, _| g.next() * 1e3);
            let b = StateMatrix::from_fn(|_, _| g.next() * 1e-2);
            let mut out = StateMatrix::zeros();
            mul_into(&a, &b, &mut out);
            assert_eq!(bits(&out), bits(&(a * b)));
            let b4 = SMatrix::<f64, 12, 4>::from_fn(|_, _| g.next());
            let k = SMatrix::<f64, 4, 12>::from_fn(|_, _| g.next() * 50.0);
            let mut out4 = StateMatrix::zeros();
            mul_into(&b4, &k, &mut out4);
            assert_eq!(bits(&out4), bits(&(b4 * k)));
        }
        // signed zeros and non-finite values propagate as in the product
        let mut a = StateMatrix::zeros();
        a[(0, 0)] = -0.0;
        a[(1, 1)] = f64::INFINITY;
        let b = StateMatrix::from_element(-0.0);
        let mut out = StateMatrix::zeros();
        mul_into(&a, &b, &mut out);
        assert_eq!(bits(&out), bits(&(a * b)));
    }

    /// Whether every eigenvalue of `a` (nalgebra's Schur form) has a real part below `-margin`.
    fn hurwitz(a: &StateMatrix, margin: f64) -> bool {
        a.complex_eigenvalues().iter().all(|l| l.re < -margin)
    }

    #[test]
    fn lyapunov_solves_the_equation() {
        // Oracle: the residual AᵀX + XA + C of the returned X, and Lyapunov's theorem (A
        // Hurwitz and C positive definite give a symmetric positive-definite X), with the
        // eigenvalues from nalgebra's Schur decomposition.
        let mut g = Lcg(11);
        let (mut solved, mut refused) = (0, 0);
        for trial in 0..300 {
            // Hurwitz-ish: -d I + noise; some trials not Hurwitz
            let shift = [3.0, 1.0, 0.2, -0.5][trial % 4];
            let noise = [0.1, 1.0, 3.0][trial % 3];
            let a =
                StateMatrix::from_fn(|i, j| g.next() * noise - if i == j { shift } else { 0.0 });
            let m = StateMatrix::from_fn(|_, _| g.next());
            let c = m * m.transpose() + StateMatrix::identity() * (0.01 + trial as f64 * 0.01);
            let x = lyapunov(&a, &c, 60);
            if hurwitz(&a, 1e-3) {
                let x = x.unwrap_or_else(|| panic!("trial {trial}: Hurwitz A not solved"));
                let residual = a.transpose() * x + x * a + c;
                let scale = a.norm() * x.norm() + c.norm();
                assert!(
                    residual.norm() <= 1e-9 * scale,
                    "trial {trial}: {}",
                    residual.norm()
                );
                assert_eq!(x, x.transpose(), "trial {trial}: X not symmetric");
                assert!(
                    x.cholesky().is_some(),
                    "trial {trial}: X not positive definite"
                );
                solved += 1;
            } else if !hurwitz(&a, -1e-3) {
                assert!(x.is_none(), "trial {trial}: an unstable A solved");
                refused += 1;
            }
        }
        assert!(
            solved > 80 && refused > 100,
            "{solved} solved, {refused} refused"
        );
        let singular = StateMatrix::zeros();
        assert!(lyapunov(&singular, &singular, 60).is_none());
        let mut nan = -StateMatrix::identity();
        nan[(3, 4)] = f64::NAN;
        assert!(lyapunov(&nan, &StateMatrix::identity(), 60).is_none());
    }
}
